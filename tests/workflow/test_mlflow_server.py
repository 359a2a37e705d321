"""The shared tracking server: PostgreSQL + ``mlflow server`` on localhost, a few stages at ``--cores 4``.

Every job of the call must arrive as a run under the call's parent run, with its tags, params, metrics and
artifacts (the stage's outputs and its log). Skipped where PostgreSQL's server binaries or psycopg2 are
missing (``apt-get install postgresql``; ``pip install -e ".[cluster]"``) or where the user is not root
(PostgreSQL runs as user ``postgres``).
"""

from __future__ import annotations

import glob
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
from tests.workflow.conftest import script_service

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "cluster" / "mlflow_server.sh"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.cluster,
    pytest.mark.skipif(not glob.glob("/usr/lib/postgresql/*/bin/initdb"), reason="PostgreSQL server not installed"),
    pytest.mark.skipif(importlib.util.find_spec("psycopg2") is None, reason="psycopg2 not installed ([cluster] extra)"),
    pytest.mark.skipif(os.geteuid() != 0, reason="starting PostgreSQL as user postgres needs root"),
]


@pytest.fixture()
def server():
    """The tracking URI of a fresh server; PostgreSQL and the server are stopped afterwards, however the test ends."""
    with script_service(SCRIPT, "topoloc-mlflow-", ("PG_PORT", "MLFLOW_PORT"), "MLFLOW_TRACKING_URI") as (uri, _):
        yield uri


def test_stages_at_four_cores_arrive_complete_on_the_server(workflow, server):
    drive = "ren00_clear_noon"
    targets = ["results/helsinki/dataset/stats.json", f"results/helsinki/odometry/{drive}/odometry.json"]
    env = {k: v for k, v in os.environ.items() if k != "TOPOLOC_INVOCATION_ID"} | {"MLFLOW_TRACKING_URI": server}
    proc = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "4", *targets], cwd=workflow.root,
                          check=False, capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not (workflow.root / "results" / "mlflow.db").exists()  # nothing went to the local store

    from mlflow import MlflowClient

    client = MlflowClient(server)
    experiment = client.get_experiment_by_name("topoloc")
    assert experiment.artifact_location.startswith("mlflow-artifacts:")  # the server keeps the artifacts
    runs = client.search_runs([experiment.experiment_id], max_results=1000)
    parents = [r for r in runs if r.data.tags.get("topoloc.role") == "pipeline"]
    assert len(parents) == 1 and parents[0].info.status == "FINISHED"
    children = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == parents[0].info.run_id]
    # one run per executed job: the jobs are those that left a benchmark file
    jobs = sorted(p.stem for p in (workflow.root / "results" / "helsinki" / "benchmarks").glob("*.tsv"))
    assert jobs == ["build_graph", "download_osm", f"extract_odometry_{drive}", "generate_dataset", f"render_drive_{drive}"]
    recorded = sorted("_".join([r.data.tags["topoloc.rule"], *([r.data.tags["topoloc.wildcards.drive"]]
                      if "topoloc.wildcards.drive" in r.data.tags else [])]) for r in children)
    assert recorded == jobs, f"runs recorded {len(recorded)} / expected {len(jobs)}"
    for run in children:
        tags, name = run.data.tags, run.data.tags["topoloc.rule"]
        assert run.info.status == "FINISHED", name
        assert tags["topoloc.wildcards.region"] == "helsinki" and tags["topoloc.code_digest"], name
        assert tags["topoloc.git_commit"] and tags["topoloc.invocation"] == parents[0].data.tags["topoloc.invocation"]
        assert any(k.startswith("topoloc.input_sha256.") for k in tags) or name == "download_osm", name
        assert run.data.params, name
        artifacts = {a.path for a in client.list_artifacts(run.info.run_id)}
        logs = {a.path for a in client.list_artifacts(run.info.run_id, "logs")}
        assert "logs" in artifacts and len(logs) == 1, name
        assert any(path.endswith((".json", ".csv", ".png", ".graphml", ".md")) for path in artifacts), name
    metrics = {r.data.tags["topoloc.rule"]: r.data.metrics for r in children}
    assert metrics["build_graph"] and metrics["generate_dataset"] and metrics["extract_odometry"]
    # an artifact's bytes are the output's
    graph_run = next(r for r in children if r.data.tags["topoloc.rule"] == "build_graph")
    local = client.download_artifacts(graph_run.info.run_id, "stats.json", str(workflow.root))
    assert Path(local).read_bytes() == (workflow.root / "results/helsinki/graph/stats.json").read_bytes()
