"""The benchmarks run as ``python -m benchmarks.<name>`` from the repository root without PYTHONPATH, and copy what
they print to a markdown file."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import topoloc
from benchmarks import bench_drive_maps, bench_filter_recovery, bench_map_errors, bench_recalibration
from benchmarks.markdown import markdown_copy

REPO = Path(__file__).resolve().parents[1]
BENCHMARKS = sorted(p.stem for p in (REPO / "benchmarks").glob("bench_*.py"))


def test_the_benchmarks_are_there():
    assert len(BENCHMARKS) == 18 and {"bench_odometry", "bench_real_drives", "bench_viewer", "bench_map_errors",
                                      "bench_filter_recovery", "bench_lane_offset", "bench_drive_maps", "bench_recalibration"} <= set(BENCHMARKS)


# Each benchmark run as ``python -m benchmarks.<name> --help`` does (runpy, as __main__, the working directory first on
# the path), all in one process: one interpreter start and one import of torch instead of one per benchmark.
HELP_EACH = """
import contextlib, io, json, runpy, sys
names, out = sys.argv[1:], {}
for name in names:
    sys.argv = [name, "--help"]
    stdout, stderr, code = io.StringIO(), io.StringIO(), 0
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            runpy.run_module("benchmarks." + name, run_name="__main__", alter_sys=True)
        except SystemExit as stop:
            code = stop.code or 0
        except BaseException as error:
            code = repr(error)
    out[name] = {"code": code, "stdout": stdout.getvalue(), "stderr": stderr.getvalue()}
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def helps() -> dict[str, dict]:
    # Only the library under test on the path (where `pip install -e .` puts it), never the repository root:
    # `benchmarks` must come from the working directory.
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env |= {"PYTHONPATH": str(Path(topoloc.__file__).parents[1]), "OMP_NUM_THREADS": "1"}
    assert Path(env["PYTHONPATH"]).resolve() != REPO.resolve()
    done = subprocess.run([sys.executable, "-c", HELP_EACH, *BENCHMARKS], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.parametrize("name", BENCHMARKS)
def test_a_benchmark_runs_without_pythonpath(name, helps):
    assert helps[name]["code"] == 0, helps[name]["stderr"]
    assert f"results/benchmarks/{name}.md" in " ".join(helps[name]["stdout"].split())  # the --out default


def test_markdown_copy_writes_what_was_printed(tmp_path, capsys):
    with markdown_copy(tmp_path / "out" / "bench.md"):
        print("| a | b |")
        print("|---|---|")
    assert capsys.readouterr().out == "| a | b |\n|---|---|\n"
    assert (tmp_path / "out" / "bench.md").read_text() == "| a | b |\n|---|---|\n"


def test_markdown_copy_leaves_no_file_when_the_benchmark_fails(tmp_path):
    with pytest.raises(RuntimeError), markdown_copy(tmp_path / "bench.md"):
        print("half")
        raise RuntimeError("stopped")
    assert not (tmp_path / "bench.md").exists()


@pytest.mark.parametrize("main, option", [
    (bench_map_errors.main, "--seeds"), (bench_filter_recovery.main, "--seeds"), (bench_drive_maps.main, "--seeds"),
    (bench_recalibration.main, "--fit-seeds"), (bench_recalibration.main, "--check-seeds")])
@pytest.mark.parametrize("seeds, why", [
    ("0,x", "not a comma-separated list of integers"), ("1,1", "names a seed twice"), ("", "not a comma-separated list")])
def test_a_bad_seed_list_is_one_line_naming_the_option_and_writes_nothing(main, option, seeds, why, tmp_path, capsys):
    args = ["--map", "a=x", "--case", "a:a"] if main is bench_drive_maps.main else []
    with pytest.raises(SystemExit) as stopped:
        main([*args, option, seeds, "--out", str(tmp_path / "x.md")])
    assert stopped.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert option in error and why in error
    assert not (tmp_path / "x.md").exists()
