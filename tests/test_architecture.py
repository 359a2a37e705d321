"""The layers of docs/architecture.md, enforced: every module of src/topoloc imports only its own or lower layers,
never a stage module, and never a topoloc module inside a function (which would hide a cycle); and the packages
of src/topoloc import each other without a cycle (two packages of one layer included)."""

from __future__ import annotations

import ast
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# Module name prefixes (without the package name) -> layer; the longest matching prefix wins.
# Stage modules (derived from the workflow scripts) form their own layer above every library.
LAYERS = {
    # 0 core: no topoloc imports beyond this layer
    "errors": 0, "io": 0, "geometry": 0, "hashing": 0, "code_digest": 0, "config": 0, "tracking": 0, "training": 0,
    "stage": 0, "localizer": 0, "report_tables": 0, "fast_inference": 0,
    # 1 map and motion: road graph, OSM, token encoding and segmentation, poses / routes / noise
    "osm": 1, "graph": 1, "encoding": 1, "segmentation": 1, "motion": 1,
    # 2 sensors: rendered images, odometry
    "render": 2, "odometry": 2,
    # 3 task libraries
    "localization": 3, "trajectory": 3, "place": 3, "drive": 3, "report": 3,
    # 4 localizers (registered implementations of topoloc.localizer) and the registry that discovers them
    "localizers": 4, "registry": 4,
    # the experiments' shared helpers (their stage modules are in the stage layer)
    "experiments": 4,
    # the viewer's library (page, belief, drive view, headless chromium helper): it runs the metric localizer
    "viewer": 4,
    # 6 entry points (5 is the stage modules)
    "cli": 6,
}
STAGE_LAYER = 5


@dataclass(frozen=True)
class Violation:
    module: str
    imported: str
    line: int
    why: str

    def __str__(self) -> str:
        return f"{self.module}:{self.line} imports {self.imported}: {self.why}"


def module_names(root: Path, package: str) -> dict[str, Path]:
    """Dotted name (without ``package.``) -> file, for every module of the package at ``root``."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def stage_modules(scripts: Path, package: str) -> set[str]:
    """Modules whose ``run`` a workflow script imports (``from <package>.<module> import run``)."""
    stages = set()
    for script in sorted(scripts.glob("*.py")):
        for node in ast.walk(ast.parse(script.read_text())):
            if (isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(package + ".")
                    and any(alias.name == "run" for alias in node.names)):
                stages.add(node.module[len(package) + 1:])
    return stages


def layer_of(module: str, stages: set[str], layers: dict[str, int]) -> int:
    """The layer of a module: the stage layer, or that of its longest prefix in ``layers``."""
    if module in stages:
        return STAGE_LAYER
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in layers:
            return layers[".".join(parts[:n])]
    raise KeyError(f"module {module!r} has no layer: add it to LAYERS and docs/architecture.md")


def _imports(tree: ast.Module, module: str, is_package: bool, package: str):
    """(imported module, line, inside a function or class) for every import of ``package`` in ``tree``."""
    nested = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)):
            nested |= {id(n) for n in ast.walk(node) if n is not node}
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = [package, *module.split(".")] if module else [package]
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # ``from package.sub import name``: ``name`` may be a submodule; check() trims it to the module.
            names = [f"{target}.{alias.name}" for alias in node.names]
        for name in names:
            if name == package or name.startswith(package + "."):
                yield name[len(package) + 1:], node.lineno, id(node) in nested


def check(root: Path, scripts: Path, package: str = "topoloc", layers: dict[str, int] | None = None) -> list[Violation]:
    """Every violation of the layering in the package at ``root`` (stages from the scripts in ``scripts``)."""
    layers = LAYERS if layers is None else layers
    modules = module_names(root, package)
    stages = stage_modules(scripts, package)
    found = []
    for module, path in modules.items():
        own = layer_of(module, stages, layers) if module else 0
        for imported, line, in_function in _imports(ast.parse(path.read_text()), module, path.name == "__init__.py", package):
            while imported not in modules and "." in imported:  # ``from pkg.mod import name``: the module
                imported = imported.rsplit(".", 1)[0]
            if in_function:
                found.append(Violation(module, imported, line, "a function-level import (move it to the top)"))
            if imported in stages and imported != module:
                found.append(Violation(module, imported, line, "a stage module (stages are leaves)"))
            elif imported in modules and imported and layer_of(imported, stages, layers) > own:
                found.append(Violation(module, imported, line, f"a higher layer ({layer_of(imported, stages, layers)} > {own})"))
    return sorted(set(found), key=str)  # one per module, import and reason


def package_imports(root: Path, package: str = "topoloc") -> dict[tuple[str, str], list[str]]:
    """(importing, imported) top-level subpackage or module of ``package`` -> the modules whose imports make
    that edge (``localization.decode_trajectories -> trajectory.model``); imports inside a package are no edge."""
    modules = module_names(root, package)
    edges: dict[tuple[str, str], list[str]] = {}
    for module, path in modules.items():
        for imported, _, _ in _imports(ast.parse(path.read_text()), module, path.name == "__init__.py", package):
            while imported not in modules and "." in imported:
                imported = imported.rsplit(".", 1)[0]
            if not module or not imported or imported not in modules:
                continue
            a, b = module.split(".")[0], imported.split(".")[0]
            if a != b and f"{module} -> {imported}" not in edges.get((a, b), []):
                edges.setdefault((a, b), []).append(f"{module} -> {imported}")
    return edges


def import_cycles(edges: Iterable[tuple[str, str]]) -> list[list[str]]:
    """The sets of nodes that import each other in a cycle (strongly connected components of more than
    one node), each sorted, in name order (Tarjan's algorithm)."""
    graph: dict[str, list[str]] = {}
    for a, b in edges:
        graph.setdefault(a, []).append(b)
        graph.setdefault(b, [])
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in graph[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


def describe_cycles(edges: dict[tuple[str, str], list[str]]) -> list[str]:
    """One line per package cycle: its packages and the module imports that close it."""
    lines = []
    for cycle in import_cycles(edges):
        inside = [f"{a} -> {b} ({', '.join(edges[a, b][:3])})" for (a, b) in sorted(edges) if a in cycle and b in cycle]
        lines.append(f"packages {' <-> '.join(cycle)} import each other: " + "; ".join(inside))
    return lines


def test_the_stages_come_from_the_workflow_scripts():
    stages = stage_modules(REPO / "workflow" / "scripts", "topoloc")
    assert {"graph.build_graph", "odometry.segment_trajectory", "place.localize_repeat", "trajectory.train_rnn"} <= stages
    assert len(stages) == 27


def test_every_module_has_a_layer():
    stages = stage_modules(REPO / "workflow" / "scripts", "topoloc")
    for module in module_names(REPO / "src" / "topoloc", "topoloc"):
        if module:
            layer_of(module, stages, LAYERS)


def test_src_follows_the_layers():
    violations = check(REPO / "src" / "topoloc", REPO / "workflow" / "scripts")
    assert not violations, "\n".join(map(str, violations))


def test_no_two_packages_import_each_other():
    edges = package_imports(REPO / "src" / "topoloc")
    assert ("localizers", "localization") in edges  # the graph is built from the real imports
    cycles = describe_cycles(edges)
    assert not cycles, "\n".join(cycles)


@pytest.mark.parametrize(("edges", "cycles"), [
    ([("a", "b"), ("b", "c"), ("a", "c")], []),
    ([("a", "b"), ("b", "a"), ("b", "c")], [["a", "b"]]),
    ([("a", "b"), ("b", "c"), ("c", "a"), ("d", "e"), ("e", "d"), ("c", "d")], [["a", "b", "c"], ["d", "e"]]),
])
def test_the_cycle_finder(edges, cycles):
    assert import_cycles(edges) == cycles


@pytest.fixture
def tiny(tmp_path):
    """A package ``pkg`` with a core module, a library, two stages and one workflow script per stage."""
    root, scripts = tmp_path / "pkg", tmp_path / "scripts"
    (root / "lib").mkdir(parents=True)
    scripts.mkdir()
    files = {
        "__init__.py": "",
        "core.py": "import os\n",
        "lib/__init__.py": "",
        "lib/util.py": "from pkg.core import x\n",
        "lib/first.py": "from pkg.lib.util import y\n\ndef run(conf, inputs, outputs):\n    import json\n",
        "lib/second.py": "from pkg.lib import util\n\ndef run(conf, inputs, outputs):\n    pass\n",
    }
    for name, text in files.items():
        (root / name).write_text(text)
    for stage in ("first", "second"):
        (scripts / f"{stage}.py").write_text(f"from pkg.lib.{stage} import run\nrun(snakemake)\n")
    return root, scripts, {"core": 0, "lib": 1}


def test_the_checker_accepts_a_clean_package(tiny):
    root, scripts, layers = tiny
    assert check(root, scripts, "pkg", layers) == []


@pytest.mark.parametrize(("module", "text", "why"), [
    ("lib/second.py", "from pkg.lib.first import run as first\n", "stage module"),
    ("lib/util.py", "from . import first\n", "stage module"),
    ("core.py", "from pkg.lib.util import y\n", "higher layer"),
    ("lib/util.py", "def f():\n    from pkg.core import x\n", "function-level"),
    ("lib/util.py", "class C:\n    import pkg.core\n", "function-level"),
])
def test_the_checker_catches_a_violation(tiny, module, text, why):
    root, scripts, layers = tiny
    (root / module).write_text(text)
    violations = check(root, scripts, "pkg", layers)
    assert len(violations) == 1 and why in violations[0].why, violations


def test_the_checker_catches_a_package_cycle(tiny):
    root, _, _ = tiny
    (root / "other").mkdir()
    (root / "other" / "__init__.py").write_text("")
    (root / "other" / "mod.py").write_text("from pkg.lib.util import y\n")
    assert describe_cycles(package_imports(root, "pkg")) == []
    (root / "lib" / "util.py").write_text("from pkg.core import x\nfrom pkg.other import mod\n")
    assert describe_cycles(package_imports(root, "pkg")) == [
        "packages lib <-> other import each other: lib -> other (lib.util -> other.mod); other -> lib (other.mod -> lib.util)"]
