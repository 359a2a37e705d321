"""Fault injection: ``kill -9`` a running stage at three moments, recover with the README's steps.

The stage is ``render_drive`` on a 300 m town (the cheapest stage that writes a temporary folder for
seconds). Moments: (a) the job's process alone while its images are in the temporary folder
(Snakemake survives and fails the job); (b) the whole process group (Snakemake and the job) at the
same moment; (c) the whole group after the job has written some of its outputs. Recovery is what the
README's "When a run was killed" says: the same command, after ``snakemake --unlock`` when Snakemake
itself was killed. Then: the run completes, no MLflow run is RUNNING, no temporary file or marker is
left, and the outputs equal those of the uninterrupted run.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

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
        if path.is_file():
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


def runs(root: Path) -> list:
    from mlflow import MlflowClient

    client = MlflowClient(f"sqlite:///{root / 'results' / 'mlflow.db'}")
    return client.search_runs([client.get_experiment_by_name("topoloc").experiment_id])


def test_kill_at_three_moments_and_recover(workflow):
    root = workflow.root
    town_osm(root / "town.osm")
    tiny = workflow.config("tiny.yaml", "region: {name: town, osm_file: town.osm}\n"
                                        "render: {length_m: 160, sheet: {conditions: [clear_noon], frames: 1}}\n")
    command = [TARGET, "--configfile", tiny]  # no --cores: the workflow profile gives it

    code, err = finish(snakemake(root, *command))
    assert code == 0, err
    reference = fingerprint(root)
    assert len(reference) > 300  # ~160 stereo pairs and the files beside them

    mid_images = lambda: any((root / DRIVE.parent).glob(f"{DRIVE.name}/.topoloc-tmp.image_0.*/image_0/000010.png"))  # noqa: E731
    some_outputs = lambda: (root / DRIVE / "calib.txt").exists()  # noqa: E731
    for moment, whole_group, reached in (("a", False, mid_images), ("b", True, mid_images), ("c", True, some_outputs)):
        shutil.rmtree(root / DRIVE)  # as on a first run: the drive is to be rendered
        before = {r.info.run_id for r in runs(root)}
        proc = snakemake(root, *command, new_session=True)
        wait_for(lambda: list((root / "results" / ".tracking").glob("run-*.json")) and reached(), proc, f"moment {moment}")
        pid = job_pid(root)
        if whole_group:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        else:
            os.kill(pid, signal.SIGKILL)
            code, err = finish(proc)
            assert code != 0
            last = err.rstrip().splitlines()[-1]
            assert last.startswith("topoloc: rule render_drive (region=town, drive=ren00_clear_noon) stopped without finishing"), err[-2000:]
        owner = process_identity(pid)
        deadline = time.monotonic() + 30  # a killed process may take a moment to be torn down
        while owner_alive(owner) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not owner_alive(owner), moment
        assert temporaries(root) or moment == "c"  # what a killed job leaves behind

        if whole_group:  # the README's recovery: unlock (without --cores), then the same command
            code, err = finish(snakemake(root, "--unlock"))
            assert code == 0, err
        code, err = finish(snakemake(root, *command))
        assert code == 0, f"moment {moment}: {err[-3000:]}"

        assert fingerprint(root) == reference, moment
        assert temporaries(root) == [], moment
        assert sorted(p.name for p in (root / "results" / ".tracking").iterdir()) == ["lock"], moment
        now = runs(root)
        assert [r.info.run_name for r in now if r.info.status == "RUNNING"] == [], moment
        new_runs = [r for r in now if r.info.run_id not in before]
        killed = sorted(r.data.tags.get("topoloc.rule", "pipeline") for r in new_runs if r.info.status == "KILLED")
        assert killed == (["pipeline", "render_drive"] if whole_group else ["render_drive"]), moment
        assert all("gone; found at" in r.data.tags["topoloc.killed"] for r in new_runs if r.info.status == "KILLED")
        assert any(r.info.status == "FINISHED" and r.data.tags.get("topoloc.rule") == "render_drive" for r in new_runs)
