"""A small two-region workflow through a real one-node Slurm on localhost, against the same run done locally.

Every job must go through sbatch (Slurm's job completion log, and squeue, list it by the job's rule), and every
result must equal the local run's byte for byte. Skipped where Slurm or munge are not installed
(``apt-get install slurm-wlm munge``), the Slurm executor plugin is missing (``pip install -e ".[cluster]"``) or
the user is not root (the daemons run as root). Several minutes: marked ``cluster`` (not in the CI budget).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from tests.workflow.conftest import script_service

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "cluster" / "slurm_local.sh"
TARGET = "results/regions/summary.csv"
#: The run's results compared byte for byte (per region, and the summary).
COMPARED = ["graph/graph.graphml", "odometry/sim00/frames.csv", "localization/sim00/answers.csv",
            "localization/localization.csv"]

pytestmark = [
    pytest.mark.slow,
    pytest.mark.cluster,
    pytest.mark.kitti,
    pytest.mark.skipif(not all(shutil.which(b) for b in ("slurmctld", "slurmd", "munged", "sbatch", "squeue")),
                       reason="Slurm or munge not installed"),
    pytest.mark.skipif(importlib.util.find_spec("snakemake_executor_plugin_slurm") is None,
                       reason="snakemake-executor-plugin-slurm not installed ([cluster] extra)"),
    pytest.mark.skipif(os.geteuid() != 0, reason="the Slurm daemons run as root"),
]


@pytest.fixture()
def slurm():
    """SLURM_CONF of a fresh one-node cluster and its folder; the daemons are stopped afterwards."""
    with script_service(SCRIPT, "topoloc-slurm-", ("SLURMCTLD_PORT", "SLURMD_PORT"), "SLURM_CONF") as started:
        yield started


def two_regions(root: Path, kitti_map: Path) -> str:
    """A small config: the default map and the KITTI 00 map, one simulated drive each, the HMM localizer."""
    (root / "k00.yaml").write_text(f"region: {{name: k00, osm_file: {kitti_map}, place: null, bbox: null}}\n")
    (root / "two.yaml").write_text("odometry: {source: simulated, simulated: {drives: 1, length_m: 600}}\n"
                                   "localization: {localizers: [hmm]}\nregions: [k00.yaml]\n")
    return "two.yaml"


def snakemake(root: Path, *args: str, env: dict[str, str] | None = None) -> None:
    env = {k: v for k, v in (env or os.environ).items() if k not in {"MLFLOW_TRACKING_URI", "TOPOLOC_INVOCATION_ID"}}
    proc = subprocess.run([sys.executable, "-m", "snakemake", TARGET, *args], check=False, cwd=root,
                          capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr[-4000:]


def test_two_regions_through_slurm_equal_a_local_run(workflow, tmp_path, kitti00, slurm):
    conf, folder = slurm
    local = tmp_path / "local"
    shutil.copytree(workflow.root, local, symlinks=True)
    config = two_regions(workflow.root, kitti00 / "map" / "kitti_00.osm")
    two_regions(local, kitti00 / "map" / "kitti_00.osm")
    snakemake(local, "--cores", "2", "--configfile", config)

    env = {**os.environ, "SLURM_CONF": conf}
    snakemake(workflow.root, "--profile", str(REPO / "profiles" / "slurm"), "--slurm-no-account", "--jobs", "4",
              "--slurm-status-command", "squeue", "--slurm-init-seconds-before-status-checks", "1",
              "--configfile", config, env=env)

    jobs = sorted(p.relative_to(local / "results") for p in (local / "results").glob("*/benchmarks/*.tsv"))
    assert len(jobs) == 13  # download, graph, odometry, segments, decoding, evaluation per region; the summary
    # every job went through sbatch: the job completion log holds one COMPLETED Slurm job per Snakemake job,
    # and the plugin names each job's rule in its comment (squeue keeps finished jobs for MinJobAge)
    completions = (folder / "jobcomp.txt").read_text().splitlines()
    assert len(completions) == len(jobs) and all("JobState=COMPLETED" in line for line in completions)
    queue = subprocess.run(["squeue", "--states=all", "-h", "-o", "%k"], check=True, capture_output=True, text=True,
                           env=env).stdout.split()
    rules = sorted(re.sub(r"_wildcards.*|^rule_", "", comment) for comment in queue)
    assert len(rules) == len(jobs) and rules.count("summarize_regions") == 1
    assert rules.count("decode_trajectories") == 1 and rules.count("k00_decode_trajectories") == 1
    assert sorted(p.relative_to(workflow.root / "results") for p in (workflow.root / "results").glob(
        "*/benchmarks/*.tsv")) == jobs
    for region in ("helsinki", "k00"):
        for name in COMPARED:
            assert (workflow.root / "results" / region / name).read_bytes() == \
                (local / "results" / region / name).read_bytes(), f"{region}/{name}"
    assert (workflow.root / TARGET).read_bytes() == (local / TARGET).read_bytes()
