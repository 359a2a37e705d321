import json
import os
import multiprocessing

import pytest

from topoloc import tracking


def test_flatten_params():
    flat = tracking.flatten_params({"graph": {"classes": ["a", "b"], "spacing": 20, "crs": None, "on": True}})
    assert flat == {"graph.classes": '["a", "b"]', "graph.spacing": "20", "graph.crs": "null", "graph.on": "true"}


def _stage(args):
    workdir, invocation, index = args
    import os

    os.chdir(workdir)
    os.environ[tracking.INVOCATION_ENV] = invocation
    with tracking.StageRun("exp", f"rule{index}", {"topoloc.wildcards.region": "r"}, {"k": index}) as run:
        run.log_metrics({"m": index})
    return run.run_id


@pytest.fixture()
def store(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    return tmp_path


def test_parallel_stage_runs_share_one_parent(store):
    """Four processes open runs at once on a fresh SQLite store: no lock errors, one parent."""
    invocation = tracking.new_invocation_id()
    with multiprocessing.get_context("spawn").Pool(4) as pool:
        run_ids = pool.map(_stage, [(str(store), invocation, i) for i in range(4)])
    from mlflow import MlflowClient

    client = MlflowClient(tracking.tracking_uri())
    experiment = client.get_experiment_by_name("exp")
    assert experiment.artifact_location == (store / "results" / "mlartifacts").as_uri()
    runs = client.search_runs([experiment.experiment_id])
    parents = [r for r in runs if r.data.tags.get("topoloc.role") == "pipeline"]
    children = [r for r in runs if "mlflow.parentRunId" in r.data.tags]
    assert len(parents) == 1 and len(children) == 4
    assert {r.info.run_id for r in children} == set(run_ids)
    assert all(r.data.tags["mlflow.parentRunId"] == parents[0].info.run_id for r in children)
    assert sorted(r.data.metrics["m"] for r in children) == [0, 1, 2, 3]
    assert {r.data.tags["topoloc.rule"] for r in children} == {"rule0", "rule1", "rule2", "rule3"}

    tracking.finish_invocation(invocation, "FINISHED")
    assert client.get_run(parents[0].info.run_id).info.status == "FINISHED"
    assert not list((store / "results" / ".tracking").glob("invocation-*"))


def test_finishing_an_invocation_without_runs_creates_nothing(store):
    tracking.finish_invocation("no-such-invocation", "FINISHED")
    assert not (store / "results" / "mlflow.db").exists()


def test_git_state_outside_a_repository(tmp_path):
    assert tracking.git_state(tmp_path) == {"topoloc.git_commit": "unknown", "topoloc.git_dirty": "unknown"}


def test_a_failing_stage_marks_its_run_failed(store):
    with pytest.raises(RuntimeError):
        with tracking.StageRun("exp", "boom", {}, {}) as run:
            raise RuntimeError("stage failed")
    from mlflow import MlflowClient

    assert MlflowClient(tracking.tracking_uri()).get_run(run.run_id).info.status == "FAILED"
    assert "MLFLOW_TRACKING_URI" not in os.environ  # the run does not leak its store to later code
    markers = list((store / "results" / ".tracking").glob("invocation-*.json"))
    assert len(markers) == 1 and json.loads(markers[0].read_text())["run_id"]


def _killed_stage(args):
    """A ``snakemake`` call whose one stage process dies with SIGKILL inside its run (kill -9, the OOM killer)."""
    workdir, invocation = args
    import signal

    os.chdir(workdir)
    os.environ[tracking.INVOCATION_ENV] = invocation
    os.environ.pop(tracking.OWNER_ENV, None)  # no snakemake process: this process owns the call too
    with tracking.StageRun("exp", "killed", {}, {}):
        os.kill(os.getpid(), signal.SIGKILL)


def test_runs_of_killed_processes_are_closed_as_killed_at_the_next_start(store, monkeypatch):
    from mlflow import MlflowClient

    live, dead = tracking.new_invocation_id(), tracking.new_invocation_id()
    monkeypatch.setenv(tracking.INVOCATION_ENV, live)
    monkeypatch.setenv(tracking.OWNER_ENV, str(os.getpid()))  # a call still running: this process
    with tracking.StageRun("exp", "finished", {}, {}):
        pass
    process = multiprocessing.get_context("spawn").Process(target=_killed_stage, args=((str(store), dead),))
    process.start()
    process.join()
    assert process.exitcode == -9
    state = store / "results" / ".tracking"
    assert len(list(state.glob("run-*.json"))) == 1 and len(list(state.glob("invocation-*.json"))) == 2

    closed = tracking.close_stale_runs()
    client = MlflowClient(tracking.tracking_uri())
    runs = client.search_runs([client.get_experiment_by_name("exp").experiment_id])
    status = {(r.data.tags["topoloc.invocation"], r.data.tags.get("topoloc.rule", "pipeline")): r.info.status for r in runs}
    assert status == {(live, "pipeline"): "RUNNING", (live, "finished"): "FINISHED", (dead, "pipeline"): "KILLED",
                      (dead, "killed"): "KILLED"}
    killed = [r for r in runs if r.info.status == "KILLED"]
    assert sorted(closed) == sorted(r.info.run_id for r in killed)
    assert all(r.data.tags["topoloc.killed"].startswith(f"process {process.pid} on ") and r.info.end_time for r in killed)
    assert [p.name for p in state.glob("*.json")] == [f"invocation-{live}.json"]  # the live call keeps its marker
    assert tracking.close_stale_runs() == []  # nothing stale: no MLflow call


def test_a_reused_pid_is_not_taken_for_the_owner():
    me = tracking.process_identity()
    assert tracking.owner_alive(me)
    assert not tracking.owner_alive({**me, "started": "0"})  # same pid, another start time
    assert tracking.owner_alive({**me, "host": "elsewhere"})  # another host cannot be checked: left alone


def test_the_default_store_uses_write_ahead_logging(store):
    """Parallel jobs write while others read: the SQLite store is switched to WAL once, by the first client."""
    import sqlite3

    with tracking.StageRun("exp", "one", {}, {"k": 1}) as run:
        run.log_metrics({"m": 1.0})
    connection = sqlite3.connect(store / "results" / "mlflow.db")
    try:
        assert connection.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    finally:
        connection.close()
