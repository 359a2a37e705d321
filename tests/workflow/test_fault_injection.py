"""Fault injection: ``kill -9`` a running stage at three moments, recover with the README's steps.

The stage is ``render_drive`` on a 300 m town (the cheapest stage that writes a temporary folder for
seconds). Moments: (a) the job's process alone while its images are in the temporary folder
(Snakemake survives and fails the job); (b) the whole process group (Snakemake and the job) at the
same moment of the recovery run; (c) the whole group after the job of the next recovery has written
some of its outputs (only ``rerun-incomplete`` of the workflow profile lets the next run go on).
Recovery is what the README's "When a run was killed" says: the same command, after
``snakemake --unlock`` when Snakemake itself was killed. Then: the run completes, no MLflow run is
RUNNING, no temporary file or marker is left, and the outputs equal those of the stage run
uninterrupted. The kills are chained (each recovery is killed in turn) to keep the test short.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from tests.render.conftest import town_osm
from tests.workflow.conftest import clean_env
from topoloc.tracking import owner_alive, process_identity

pytestmark = pytest.mark.slow

DRIVE = Path("results/town/render/ren00_clear_noon")
TARGET = str(DRIVE / "render.json")
TIMING_KEYS = {"render_s", "render_pairs_per_s", "render_pairs_per_cpu_s", "render_and_write_s", "pairs_per_s_with_png",
               "scene_s"}


def snakemake(root: Path, *args: str, new_session: bool = False) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "snakemake", *args], cwd=root, env=clean_env(), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=new_session)


def finish(proc: subprocess.Popen) -> tuple[int, str]:
    _, err = proc.communicate(timeout=600)
    return proc.returncode, err


def fingerprint(root: Path) -> dict[str, str]:
    """sha256 of every output of the drive (render.json without its timings)."""
    prints = {}
    for path in sorted((root / DRIVE).rglob("*")):
        if path.is_file() and path.name != ".snakemake_timestamp":  # Snakemake's mark in directory outputs
            data = path.read_bytes()
            if path.name == "render.json":
                data = json.dumps({k: v for k, v in json.loads(data).items() if k not in TIMING_KEYS}, sort_keys=True).encode()
            prints[str(path.relative_to(root))] = hashlib.sha256(data).hexdigest()
    return prints


def wait_for(condition, proc: subprocess.Popen, what: str, timeout_s: float = 300.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if proc.poll() is not None:
            raise AssertionError(f"snakemake ended before {what}: {proc.communicate()[1][-3000:]}")
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


def job_pid(root: Path) -> int:
    """The pid of the running stage's process, from its MLflow run marker."""
    markers = list((root / "results" / ".tracking").glob("run-*.json"))
    assert len(markers) == 1, markers
    return json.loads(markers[0].read_text())["pid"]


def temporaries(root: Path) -> list[Path]:
    return [p for p in (root / "results").rglob(".topoloc-tmp.*")]


def mid_images(root: Path) -> bool:
    """The job is rendering: its temporary folder holds some images."""
    return any((root / DRIVE).glob(".topoloc-tmp.image_0.*/image_0/000010.png"))


def some_outputs(root: Path) -> bool:
    """The job has written some of its outputs (not yet all)."""
    return (root / DRIVE / "calib.txt").exists()


def runs(root: Path) -> list:
    from mlflow import MlflowClient

    client = MlflowClient(f"sqlite:///{root / 'results' / 'mlflow.db'}")
    return client.search_runs([client.get_experiment_by_name("topoloc").experiment_id])


def reference_render(root: Path, tiny: str, into: Path) -> None:
    """The drive rendered in this process by the stage's function, uninterrupted, from the graph the workflow built."""
    from topoloc.config import load
    from topoloc.render.render_drive import run

    config = load(root / "config" / "config.yaml", yaml.safe_load((root / tiny).read_text()))
    names = {"left": "image_0", "right": "image_1", "calib": "calib.txt", "poses": "poses.txt", "times": "times.txt",
             "gps": "gps.csv", "route": "route.csv", "stats": "render.json", "sheet": "contact_sheet.png"}
    inputs = {"osm": str(root / "results/town/osm/region.osm"), "graph": str(root / "results/town/graph/graph.graphml")}
    run({**config["render"], "drive": DRIVE.name}, inputs, {k: str(into / DRIVE / v) for k, v in names.items()})


def kill_at(root: Path, command: list[str], moment: str, whole_group: bool, reached) -> tuple[int, str]:
    """Start ``snakemake COMMAND``; at ``moment`` (once ``reached``) SIGKILL the job's process or the whole group."""
    proc = snakemake(root, *command, new_session=True)
    wait_for(lambda: list((root / "results" / ".tracking").glob("run-*.json")) and reached(root), proc, f"moment {moment}")
    owner = process_identity(job_pid(root))
    if whole_group:
        os.killpg(proc.pid, signal.SIGKILL)
        code, err = proc.wait(), ""
    else:
        os.kill(owner["pid"], signal.SIGKILL)
        code, err = finish(proc)
    deadline = time.monotonic() + 30  # a killed process may take a moment to be torn down
    while owner_alive(owner) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not owner_alive(owner) and code != 0, moment
    return code, err


def test_kill_at_three_moments_and_recover(workflow, tmp_path):
    root = workflow.root
    town_osm(root / "town.osm")
    tiny = workflow.config("tiny.yaml", "region: {name: town, osm_file: town.osm}\n"
                                        "render: {length_m: 100, sheet: {conditions: [clear_noon], frames: 1}}\n")
    command = [TARGET, "--configfile", tiny]  # no --cores: the workflow profile gives it

    # (a) The job's process alone, while its images are in the temporary folder: Snakemake survives, fails the
    # job, closes its MLflow run as KILLED and ends with the job's line.
    _, err = kill_at(root, command, "a", False, mid_images)
    assert err.rstrip().splitlines()[-1] == ("topoloc: rule render_drive (region=town, drive=ren00_clear_noon) stopped "
                                             "without finishing (killed?); its log: results/town/logs/render_drive_ren00_clear_noon.log")
    left_by_a = temporaries(root)
    assert [p.name.split(".")[2] for p in left_by_a] == ["image_0"]  # .topoloc-tmp.image_0.*
    assert {r.data.tags.get("topoloc.rule", "pipeline"): r.info.status for r in runs(root)}["render_drive"] == "KILLED"

    # (b) Recovery, step 1: the same command; it removes what (a) left, and is itself killed, Snakemake with it.
    kill_at(root, command, "b", True, mid_images)
    assert not any(p.exists() for p in left_by_a)
    # (c) Recovery again (snakemake was killed: --unlock, then the same command), killed after some outputs exist.
    code, err = finish(snakemake(root, "--unlock"))
    assert code == 0, err
    assert [r.info.status for r in runs(root) if r.info.status == "RUNNING"] == []  # closed when --unlock started
    kill_at(root, command, "c", True, some_outputs)
    assert (root / DRIVE / "calib.txt").exists() and not (root / DRIVE / "render.json").exists()

    code, err = finish(snakemake(root, "--unlock"))
    assert code == 0, err
    code, err = finish(snakemake(root, *command))
    assert code == 0, err[-3000:]

    reference_render(root, tiny, tmp_path / "reference")
    expected = fingerprint(tmp_path / "reference")
    assert len(expected) > 200 and fingerprint(root) == expected  # ~110 stereo pairs and the files beside them
    assert temporaries(root) == []
    assert sorted(p.name for p in (root / "results" / ".tracking").iterdir()) == ["lock"]
    statuses = sorted((r.data.tags.get("topoloc.rule", "pipeline"), r.info.status) for r in runs(root))
    assert [s for s in statuses if s[0] == "render_drive"] == [("render_drive", "FINISHED")] + [("render_drive", "KILLED")] * 3
    assert [s for s in statuses if s[0] == "pipeline"] == [("pipeline", "FAILED"), ("pipeline", "FINISHED")] + [
        ("pipeline", "KILLED")] * 2
    assert all("gone; found at" in r.data.tags["topoloc.killed"] for r in runs(root) if r.info.status == "KILLED")
