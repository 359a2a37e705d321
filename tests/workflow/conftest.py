"""Run the Snakemake workflow in a scratch copy of the repository."""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from topoloc.config import deep_merge

REPO = Path(__file__).resolve().parents[2]


def clean_env() -> dict[str, str]:
    """This environment without the variables a ``snakemake`` call sets for its jobs (tracking store, invocation)."""
    drop = {"MLFLOW_TRACKING_URI", "TOPOLOC_INVOCATION_ID", "TOPOLOC_INVOCATION_PID"}
    return {k: v for k, v in os.environ.items() if k not in drop}



def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_for_http(url: str, server: subprocess.Popen, name: str, seconds: float = 120.0) -> None:
    """Wait until ``url`` answers; fail if ``server`` exits first or ``seconds`` pass."""
    deadline = time.monotonic() + seconds
    while True:
        try:
            urllib.request.urlopen(url, timeout=2)
            return
        except OSError:
            assert server.poll() is None, f"{name} exited"
            assert time.monotonic() < deadline, f"{name} did not answer within {seconds:.0f} s"
            time.sleep(0.5)


@contextmanager
def script_service(script: Path, prefix: str, port_vars: tuple[str, ...], export: str) -> Iterator[tuple[str, Path]]:
    """Start a local service with ``bash script start FOLDER`` (a fresh folder under /tmp, free ports in the
    environment variables ``port_vars``), yield the value of the ``export NAME=`` line it prints and its folder,
    and stop it with ``bash script stop FOLDER`` however the caller ends."""
    folder = Path(tempfile.mkdtemp(prefix=prefix, dir="/tmp"))  # the service's own user must enter it
    folder.chmod(0o755)
    env = {**os.environ, **{var: str(free_port()) for var in port_vars}}
    started = subprocess.run(["bash", str(script), "start", str(folder)], check=False, capture_output=True, text=True,
                             env=env)
    try:
        assert started.returncode == 0, started.stderr
        yield started.stdout.strip().removeprefix(f"export {export}="), folder
    finally:
        subprocess.run(["bash", str(script), "stop", str(folder)], check=False, capture_output=True, env=env)
        shutil.rmtree(folder, ignore_errors=True)


@dataclass
class Workflow:
    root: Path

    def run(self, *args: str, check: bool = True) -> subprocess.CompletedProcess:
        """``snakemake ARGS`` in the copy; raise with its output when it fails and ``check``."""
        env = clean_env()
        proc = subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=self.root, capture_output=True, text=True, env=env)
        if check and proc.returncode != 0:
            raise AssertionError(f"snakemake {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
        return proc

    def planned(self, *args: str) -> dict[str, int]:
        """Jobs a dry run of ``snakemake ARGS`` would execute, per rule (``all`` left out)."""
        out = self.run("-n", *args).stdout
        if "Nothing to be done" in out:
            return {}
        table = out.split("Job stats:", 1)[1].split("total", 1)[0]
        jobs = dict((rule, int(n)) for rule, n in re.findall(r"^(\w+)\s+(\d+)$", table, flags=re.M))
        jobs.pop("all", None)
        return jobs

    def config(self, name: str, text: str) -> str:
        """Write an extra config file and return its path relative to the copy."""
        (self.root / name).write_text(text)
        return name


@pytest.fixture()
def workflow(tmp_path) -> Workflow:
    """A scratch copy of the workflow, config and library sources (for code digests)."""
    root = tmp_path / "repo"
    root.mkdir()
    shutil.copy(REPO / "Snakefile", root)
    (root / "profiles").symlink_to("workflow/profiles")  # the workflow profile, as in the checkout
    for folder in ("workflow", "config", "src"):
        shutil.copytree(REPO / folder, root / folder, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    # The pipeline's mechanics are under test here, not accuracy: small data and training budgets.
    config_path = root / "config" / "config.yaml"
    config = deep_merge(yaml.safe_load(config_path.read_text()), {
        "odometry": {"simulated": {"drives": 1}},
        "render": {"length_m": 120, "sheet": {"conditions": ["clear_noon", "night"], "frames": 2}},
        "dataset": {"max_paths_total": 2000, "simulated": {"drives": 40, "length_m": [300, 600]}},
        # 32 training drives make one step per epoch: log every step
        "train": {"log_every_n_steps": 1, "max_epochs": 2, "max_time_min": 0.5},
        "place": {"image": {"width": 64, "height": 48},
                  "train": {"routes": 3, "val_routes": 1, "route_length_m": 120, "min_distance_m": 30, "min_frames": 20,
                            "batch_size": 8, "batches_per_epoch": 4, "max_epochs": 1, "max_time_min": 0.5,
                            "val_pairs": 16},
                  "network": {"channels": [8, 16], "embedding_dim": 16, "hidden": 32}},
        # the drive stages end to end: three demonstration routes, controllers of 8 small batches (they barely move,
        # so every drive lasts until its timeout: 60 m routes), no closed-loop check after training
        "drive": {"demonstrations": {"routes": 3},
                  "network": {"channels": [8, 16], "hidden": 32},
                  "train": {"batch_size": 16, "batches_per_epoch": 4, "max_epochs": 2, "log_every_n_steps": 1},
                  "check": {"routes": 0}, "follow": {"length_m": 60}},
    })
    config_path.write_text(yaml.safe_dump(config, sort_keys=False))
    return Workflow(root)
