"""Code digests for caching: a stage's code, from the import closure of its module.

A stage's code digest covers the import closure of its module within the
``topoloc`` package (:func:`import_closure`), found by reading the sources
with :mod:`ast`, not by importing them: every ``import`` and ``from ... import``
(absolute or relative, at module level or inside functions), the ``__init__``
of every package on the way, and the packages a module discovers at run time
(a literal ``importlib.import_module("pkg")`` in a module that also walks
packages with ``pkgutil.iter_modules`` / ``walk_packages``: every module of
``pkg`` counts, as the localizer registry imports them all).
"""

from __future__ import annotations

import ast
import functools
import hashlib
from collections.abc import Iterable, Iterator
from pathlib import Path

#: The package whose code digests are computed (the directory of this module).
PACKAGE_ROOT = Path(__file__).resolve().parent

#: Modules that cannot change a stage's results, left out of every closure (and not followed):
#: MLflow tracking, and the stage runner (logging, tags, MLflow run around ``run()``).
GLUE_MODULES = frozenset({"topoloc.tracking", "topoloc.stage"})

_DISCOVERY_FUNCTIONS = {"iter_modules", "walk_packages"}


def module_file(name: str, root: Path = PACKAGE_ROOT) -> Path | None:
    """The source of module ``name`` (dotted, starting with the package ``root.name``), or None.

    A package's source is its ``__init__.py``; None when ``name`` is no module
    under ``root`` (for example a function imported with ``from ... import``).
    """
    parts = name.split(".")
    if parts[0] != root.name:
        return None
    base = root.joinpath(*parts[1:])
    for candidate in (base / "__init__.py", base.with_suffix(".py")) if len(parts) > 1 else (root / "__init__.py",):
        if candidate.is_file():
            return candidate
    return None


def _called_name(call: ast.Call) -> str | None:
    """``f`` for a call ``f(...)`` or ``x.f(...)``."""
    if isinstance(call.func, ast.Name):
        return call.func.id
    if isinstance(call.func, ast.Attribute):
        return call.func.attr
    return None


def _package_modules(package: str, root: Path) -> Iterator[str]:
    """Every module name under the package ``package`` (recursively)."""
    directory = root.joinpath(*package.split(".")[1:])
    for file in sorted(directory.rglob("*.py")):
        parts = file.relative_to(root).with_suffix("").parts
        yield ".".join((root.name, *(parts[:-1] if parts[-1] == "__init__" else parts)))


def imported_names(file: Path, name: str, root: Path = PACKAGE_ROOT) -> set[str]:
    """Dotted names of the package ``root.name`` that module ``name`` (source ``file``) imports.

    ``from a import b`` gives both ``a`` and ``a.b`` (``b`` may be a submodule);
    names that are not modules are dropped later by :func:`module_file`.
    """
    stat = file.stat()
    names, literal_imports, discovers = _parse_imports(file, name, stat.st_mtime_ns, stat.st_size)
    names = set(names)
    if discovers:  # the package's modules as they are now (not cached: a new plugin module counts)
        for imported in literal_imports:
            source = module_file(imported, root)
            if source is not None and source.name == "__init__.py":
                names.update(_package_modules(imported, root))
    return {n for n in names if n == root.name or n.startswith(root.name + ".")}


@functools.lru_cache(maxsize=4096)
def _parse_imports(file: Path, name: str, mtime_ns: int, size: int) -> tuple[frozenset[str], frozenset[str], bool]:
    """Imported names, literal ``import_module`` arguments, and whether the module walks packages.

    Parsed once per version of the file (a workflow digests many closures that share modules).
    """
    tree = ast.parse(file.read_bytes(), filename=str(file))
    package = name if file.name == "__init__.py" else name.rpartition(".")[0]
    names: set[str] = set()
    literal_imports: set[str] = set()
    discovers = False
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
        elif isinstance(node, ast.Call):
            called = _called_name(node)
            if called in _DISCOVERY_FUNCTIONS:
                discovers = True
            elif called == "import_module" and node.args and isinstance(node.args[0], ast.Constant) \
                    and isinstance(node.args[0].value, str):
                literal_imports.add(node.args[0].value)
    return frozenset(names | literal_imports), frozenset(literal_imports), discovers


def import_closure(module_name: str, root: Path = PACKAGE_ROOT,
                   exclude: Iterable[str] = GLUE_MODULES) -> set[Path]:
    """Source files of ``module_name`` and of every module of the package it imports, transitively.

    ``root`` is the package directory (its name is the package name); modules
    in ``exclude`` are left out and their imports not followed. ModuleNotFoundError
    if ``module_name`` has no source under ``root``.
    """
    root = Path(root)
    excluded = set(exclude)
    if module_file(module_name, root) is None:
        raise ModuleNotFoundError(f"{module_name}: no module of that name under {root}")
    files: set[Path] = set()
    seen: set[str] = set()
    pending = [module_name]
    while pending:
        name = pending.pop()
        if name in seen or name in excluded:
            continue
        seen.add(name)
        file = module_file(name, root)
        if file is None:
            continue
        files.add(file)
        parts = name.split(".")
        pending.extend(".".join(parts[:i]) for i in range(1, len(parts)))  # the packages' __init__ run first
        pending.extend(imported_names(file, name, root))
    return files


def code_digest_of(module_name: str, root: Path = PACKAGE_ROOT,
                   exclude: Iterable[str] = GLUE_MODULES) -> str:
    """Short digest of the sources in the import closure of ``module_name`` (see :func:`import_closure`).

    Rules take it as a param, so editing a module reruns exactly the stages
    whose module imports it. Files are hashed by path relative to ``root`` and
    bytes, in sorted order, so the digest is the same on every machine.
    """
    root = Path(root)
    digest = hashlib.sha256()
    for file in sorted(import_closure(module_name, root, exclude), key=lambda f: f.relative_to(root).as_posix()):
        digest.update(file.relative_to(root).as_posix().encode() + b"\0")
        digest.update(file.read_bytes() + b"\0")
    return digest.hexdigest()[:16]
