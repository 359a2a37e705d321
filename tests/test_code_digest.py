"""Code digests from import closures: the closure holds what a stage really imports, and nothing of the glue."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from topoloc.code_digest import (
    GLUE_MODULES,
    PACKAGE_ROOT,
    code_digest_of,
    import_closure,
    module_file,
)

REPO = Path(__file__).resolve().parents[1]
SCRIPTS = REPO / "workflow" / "scripts"
RULES = REPO / "workflow" / "rules"


def stage_modules() -> dict[str, str]:
    """Workflow script name -> the stage module it imports ``run`` from (an experiment's aggregate: ``summarize``,
    its baseline job: ``baseline``)."""
    stages = {}
    for script in sorted(SCRIPTS.glob("*.py")):
        found = re.search(r"^from (topoloc[\w.]*) import (?:run|summarize|baseline)$", script.read_text(), re.MULTILINE)
        if found:
            stages[script.name] = found.group(1)
    return stages


STAGES = sorted(set(stage_modules().values()))

# Imports each stage in turn (topoloc dropped from sys.modules in between, third-party modules kept),
# runs the localizer registry's discovery where the stage loaded it (it imports topoloc.localizers at
# run time, not at import), and prints the files of the loaded topoloc modules.
_PROBE = """
import importlib, json, sys
loaded = {}
for stage in sys.argv[1:]:
    for name in [n for n in sys.modules if n == "topoloc" or n.startswith("topoloc.")]:
        del sys.modules[name]
    importlib.import_module(stage)
    if "topoloc.registry" in sys.modules:
        sys.modules["topoloc.registry"].registry()
    loaded[stage] = sorted(m.__file__ for n, m in list(sys.modules.items())
                           if (n == "topoloc" or n.startswith("topoloc.")) and getattr(m, "__file__", None))
print(json.dumps(loaded))
"""


@pytest.fixture(scope="module")
def really_loaded() -> dict[str, set[Path]]:
    """Stage module -> files of the topoloc modules that importing it (and its registry discovery) loads."""
    result = subprocess.run([sys.executable, "-c", _PROBE, *STAGES], capture_output=True, text=True, check=True,
                            cwd=REPO, env={**os.environ, "PYTHONPATH": str(PACKAGE_ROOT.parent)})
    loaded = json.loads(result.stdout)
    return {stage: {Path(f).resolve() for f in files} for stage, files in loaded.items()}


@pytest.fixture
def package_copy(tmp_path: Path) -> Path:
    """A copy of src/topoloc to edit."""
    return Path(shutil.copytree(PACKAGE_ROOT, tmp_path / "topoloc", ignore=shutil.ignore_patterns("__pycache__")))


def relative(files: set[Path], root: Path = PACKAGE_ROOT) -> set[str]:
    return {file.relative_to(root).as_posix() for file in files}


def test_every_script_has_a_stage_module() -> None:
    assert len(STAGES) >= 14
    assert all(module_file(stage) is not None for stage in STAGES)


def test_every_rule_digests_its_scripts_stage_module() -> None:
    """Each rule that runs a stage script has one ``code=code("<the module the script imports run from>")``."""
    stages = stage_modules()
    checked = set()
    for smk in RULES.glob("*.smk"):
        for block in re.split(r"(?m)^(?=[ \t]*rule \w+:)", smk.read_text())[1:]:
            rule = block.strip().split(":")[0].removeprefix("rule ")  # rules under an `if` are indented
            script = re.search(r'"\.\./scripts/(\w+\.py)"', block)
            if not script or script.group(1) not in stages:
                continue
            assert re.findall(r"code=code\(\"([\w.]+)\"\)", block) == [stages[script.group(1)]], rule
            checked.add(script.group(1))
    assert checked == set(stages)


@pytest.mark.parametrize("stage", STAGES)
def test_closure_contains_what_the_stage_really_imports(stage: str, really_loaded: dict[str, set[Path]]) -> None:
    glue = {module_file(name) for name in GLUE_MODULES}
    missing = really_loaded[stage] - glue - import_closure(stage)
    assert not missing, f"{stage} imports {sorted(relative(missing))} but its code digest does not cover them"


@pytest.mark.parametrize("stage", STAGES)
def test_closure_leaves_out_the_glue(stage: str) -> None:
    closure = relative(import_closure(stage))
    assert "tracking.py" not in closure and "stage.py" not in closure
    assert f"{stage.removeprefix('topoloc.').replace('.', '/')}.py" in closure
    assert "__init__.py" in closure


def test_localizer_closure_holds_every_registered_localizer_module() -> None:
    closure = import_closure("topoloc.registry")
    assert set((PACKAGE_ROOT / "localizers").glob("*.py")) <= closure


def test_editing_tracking_reruns_nothing(package_copy: Path) -> None:
    before = {stage: code_digest_of(stage, package_copy) for stage in STAGES}
    with open(package_copy / "tracking.py", "a") as handle:
        handle.write("\nEDITED = True\n")
    assert {stage: code_digest_of(stage, package_copy) for stage in STAGES} == before


def test_editing_the_hmm_reruns_exactly_the_stages_that_import_it(package_copy: Path,
                                                                   really_loaded: dict[str, set[Path]]) -> None:
    hmm = PACKAGE_ROOT / "localization" / "hmm.py"
    users = {stage for stage, files in really_loaded.items() if hmm in files}
    assert "topoloc.localization.decode_trajectories" in users
    before = {stage: code_digest_of(stage, package_copy) for stage in STAGES}
    with open(package_copy / "localization" / "hmm.py", "a") as handle:
        handle.write("\nEDITED = True\n")
    changed = {stage for stage in STAGES if code_digest_of(stage, package_copy) != before[stage]}
    assert changed == users


def test_digest_is_independent_of_where_the_package_lies(tmp_path: Path) -> None:
    one = shutil.copytree(PACKAGE_ROOT, tmp_path / "a" / "topoloc", ignore=shutil.ignore_patterns("__pycache__"))
    two = shutil.copytree(PACKAGE_ROOT, tmp_path / "b" / "c" / "topoloc", ignore=shutil.ignore_patterns("__pycache__"))
    stage = "topoloc.localization.decode_trajectories"
    assert code_digest_of(stage, one) == code_digest_of(stage, two) == code_digest_of(stage)


def write_package(root: Path, files: dict[str, str]) -> Path:
    for name, source in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(source))
    return root


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    """A synthetic package ``pkg`` with every import form the walker must follow (and some it must not)."""
    return write_package(tmp_path / "pkg", {
        "__init__.py": "",
        "a.py": """
            import numpy
            from . import b
            from .sub import c
            from pkg import glue
            from pkg.e import thing
        """,
        "b.py": "import pkg.sub.d as dd\n",
        "sub/__init__.py": "",
        "sub/c.py": "from ..e import thing\nfrom .. import registry\n",
        "sub/d.py": "def later():\n    from pkg import lazy\n    return lazy\n",
        "e.py": "thing = 1\n",
        "lazy.py": "",
        "glue.py": "import pkg.only_glue\n",
        "only_glue.py": "",
        "unused.py": "",
        "registry.py": """
            import importlib
            import pkgutil

            def discover():
                package = importlib.import_module("pkg.plugins")
                return [m.name for m in pkgutil.iter_modules(package.__path__)]
        """,
        "plugins/__init__.py": "",
        "plugins/one.py": "",
        "plugins/two.py": "from pkg.sub import c\n",
        "notdiscovered/__init__.py": "import importlib\nimportlib.import_module('pkg.other')\n",
        "other/__init__.py": "",
        "other/skipped.py": "",
    })


def test_walker_follows_absolute_relative_from_and_discovery_imports(tiny: Path) -> None:
    closure = relative(import_closure("pkg.a", tiny, exclude={"pkg.glue"}), tiny)
    assert closure == {"__init__.py", "a.py", "b.py", "sub/__init__.py", "sub/c.py", "sub/d.py", "e.py", "lazy.py",
                       "registry.py", "plugins/__init__.py", "plugins/one.py", "plugins/two.py"}


def test_a_new_module_in_a_discovered_package_changes_the_digest(tiny: Path) -> None:
    before = code_digest_of("pkg.registry", tiny)
    (tiny / "plugins" / "three.py").write_text("")
    assert "plugins/three.py" in relative(import_closure("pkg.registry", tiny), tiny)
    assert code_digest_of("pkg.registry", tiny) != before


def test_literal_import_without_pkgutil_is_one_import_not_a_discovery(tiny: Path) -> None:
    closure = relative(import_closure("pkg.notdiscovered", tiny, exclude=()), tiny)
    assert closure == {"__init__.py", "notdiscovered/__init__.py", "other/__init__.py"}


def test_excluded_module_is_left_out_and_not_followed(tiny: Path) -> None:
    with_glue = relative(import_closure("pkg.a", tiny, exclude=()), tiny)
    assert {"glue.py", "only_glue.py"} <= with_glue
    assert code_digest_of("pkg.a", tiny, exclude=()) != code_digest_of("pkg.a", tiny, exclude={"pkg.glue"})


def test_unknown_module_is_an_error(tiny: Path) -> None:
    with pytest.raises(ModuleNotFoundError, match="pkg.nope"):
        import_closure("pkg.nope", tiny)
