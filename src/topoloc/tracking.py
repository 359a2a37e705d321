"""MLflow tracking: one run per stage execution, children of one run per ``snakemake`` call.

Each Snakemake job runs in its own process, so the parent run cannot be shared
in memory. The Snakefile sets :data:`INVOCATION_ENV` once per ``snakemake``
call (child processes inherit it); the first job of that call to reach MLflow
creates the parent run and leaves a marker file with its id, under a file
lock, so a call that executes nothing creates no run at all. ``onsuccess`` /
``onerror`` close the parent with :func:`finish_invocation`.

A run whose process dies without closing it (``kill -9``, an out-of-memory kill, a pre-empted job)
would stay RUNNING forever. Every open run therefore has a marker in ``results/.tracking/`` naming its
owner process (pid, host and the process's start time, so a reused pid is not mistaken for it): the
job's process for a stage run, the ``snakemake`` process (:data:`OWNER_ENV`) for the parent. The
Snakefile calls :func:`close_stale_runs` when the workflow starts (and in ``onerror``): runs whose owner
process is gone are closed as KILLED, tagged with the time they were found, and their markers removed.

The default store is SQLite at ``results/mlflow.db`` with artifacts in
``results/mlartifacts``; ``MLFLOW_TRACKING_URI`` points elsewhere (a shared
``mlflow server``). Writers wait on SQLite's lock (``timeout``) instead of
failing, store creation is serialized, and the store is switched to WAL
journaling (readers do not block the writer), so parallel jobs are safe.

MLflow is imported lazily: the Snakefile imports this module on every call,
including dry runs and no-op reruns, which must stay fast.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sqlite3
import subprocess
import time
import uuid
from collections.abc import Iterator, Mapping
from contextlib import closing, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mlflow import MlflowClient

INVOCATION_ENV = "TOPOLOC_INVOCATION_ID"
#: The pid of the ``snakemake`` process that owns the invocation's parent run (set by the Snakefile).
OWNER_ENV = "TOPOLOC_INVOCATION_PID"
RESULTS_DIR = Path("results")
_STATE_DIR = RESULTS_DIR / ".tracking"
_SQLITE_TIMEOUT_S = 120
_MAX_PARAM_CHARS = 6000


def new_invocation_id() -> str:
    """A fresh id for one ``snakemake`` call."""
    return time.strftime("%Y%m%d-%H%M%S-") + uuid.uuid4().hex[:8]


def default_tracking_uri() -> str:
    """The SQLite store under ``results/`` (absolute path; writers wait up to two minutes on its lock)."""
    return f"sqlite:///{(RESULTS_DIR / 'mlflow.db').resolve()}?timeout={_SQLITE_TIMEOUT_S}"


def tracking_uri() -> str:
    """``MLFLOW_TRACKING_URI`` if set, else :func:`default_tracking_uri`."""
    return os.environ.get("MLFLOW_TRACKING_URI") or default_tracking_uri()


def artifact_root() -> str | None:
    """Artifact location for new experiments: ``results/mlartifacts`` in the default store, else the server's choice."""
    # mlflow.set_tracking_uri exports MLFLOW_TRACKING_URI, so compare instead of testing for the variable.
    if tracking_uri() != default_tracking_uri():
        return None
    return (RESULTS_DIR / "mlartifacts").resolve().as_uri()


@contextmanager
def _locked() -> Iterator[None]:
    _STATE_DIR.mkdir(parents=True, exist_ok=True)
    with open(_STATE_DIR / "lock", "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _client() -> MlflowClient:
    from mlflow import MlflowClient

    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    with _locked():  # the first client of a new SQLite store runs its migrations
        client = MlflowClient(tracking_uri())
        client.search_experiments(max_results=1)
        if tracking_uri() == default_tracking_uri():
            _use_wal(RESULTS_DIR / "mlflow.db")
    return client


def _use_wal(db: Path) -> None:
    """Switch the SQLite store to write-ahead logging (kept in the file; a no-op once done)."""
    with closing(sqlite3.connect(db, timeout=_SQLITE_TIMEOUT_S)) as connection:
        if connection.execute("PRAGMA journal_mode").fetchone()[0].lower() != "wal":
            connection.execute("PRAGMA journal_mode=WAL")


def _experiment_id(client: MlflowClient, name: str) -> str:
    with _locked():
        experiment = client.get_experiment_by_name(name)
        if experiment is not None:
            return experiment.experiment_id
        return client.create_experiment(name, artifact_location=artifact_root())


def git_state(repo: str | Path = ".") -> dict[str, str]:
    """The commit of ``repo`` and whether its tracked files differ from it ('unknown' outside git)."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, check=True).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.CalledProcessError):
        return {"topoloc.git_commit": "unknown", "topoloc.git_dirty": "unknown"}
    return {"topoloc.git_commit": commit, "topoloc.git_dirty": str(dirty).lower()}


def _parent_run_id(client: MlflowClient, experiment_id: str, invocation: str) -> str:
    marker = _STATE_DIR / f"invocation-{invocation}.json"
    with _locked():
        if marker.exists():
            return json.loads(marker.read_text())["run_id"]
        tags = {
            "mlflow.runName": f"snakemake {invocation}",
            "topoloc.invocation": invocation,
            "topoloc.role": "pipeline",
            **git_state(),
        }
        run = client.create_run(experiment_id, tags=tags)
        owner = process_identity(int(os.environ.get(OWNER_ENV) or os.getpid()))
        marker.write_text(json.dumps({"run_id": run.info.run_id, "experiment_id": experiment_id, **owner}))
        return run.info.run_id


def finish_invocation(invocation: str | None, status: str) -> None:
    """Close the parent run of ``invocation`` with ``status`` (FINISHED or FAILED), if one was made."""
    if not invocation:
        return
    marker = _STATE_DIR / f"invocation-{invocation}.json"
    if not marker.exists():
        return
    client = _client()
    client.set_terminated(json.loads(marker.read_text())["run_id"], status=status)
    marker.unlink(missing_ok=True)


def flatten_params(conf: Mapping[str, Any], prefix: str = "") -> dict[str, str]:
    """Nested config slice -> flat ``a.b.c`` params; lists as JSON; values cut to MLflow's limit."""
    flat: dict[str, str] = {}
    for key, value in conf.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten_params(value, f"{name}."))
        else:
            text = json.dumps(value) if isinstance(value, list | tuple | bool) or value is None else str(value)
            flat[name] = text[:_MAX_PARAM_CHARS]
    return flat


class StageRun:
    """The MLflow run of one stage execution (a context manager; the run is active inside it)."""

    def __init__(self, experiment: str, rule: str, tags: Mapping[str, str], params: Mapping[str, Any]) -> None:
        self.experiment = experiment
        self.rule = rule
        self.tags = dict(tags)
        self.params = flatten_params(params)
        self.run_id: str | None = None
        self._saved_env: str | None = None

    def __enter__(self) -> StageRun:
        import mlflow

        client = _client()
        # set_tracking_uri exports MLFLOW_TRACKING_URI; restore it on exit so it does not leak.
        self._saved_env = os.environ.get("MLFLOW_TRACKING_URI")
        mlflow.set_tracking_uri(tracking_uri())
        experiment_id = _experiment_id(client, self.experiment)
        invocation = os.environ.get(INVOCATION_ENV) or new_invocation_id()
        tags = {
            **self.tags,
            **git_state(),
            "topoloc.rule": self.rule,
            "topoloc.invocation": invocation,
            "mlflow.parentRunId": _parent_run_id(client, experiment_id, invocation),
        }
        run = mlflow.start_run(experiment_id=experiment_id, run_name=tags.get("mlflow.runName", self.rule), tags=tags)
        self.run_id = run.info.run_id
        _write_run_marker(self.run_id)
        if self.params:
            mlflow.log_params(self.params)
        return self

    def log_metrics(self, metrics: Mapping[str, float]) -> None:
        """Log scalar metrics of the stage."""
        import mlflow

        mlflow.log_metrics({k: float(v) for k, v in metrics.items()})

    def log_artifact(self, path: str | Path, artifact_path: str | None = None) -> None:
        """Attach a file to the run."""
        import mlflow

        mlflow.log_artifact(str(path), artifact_path)

    def __exit__(self, exc_type: type | None, exc: BaseException | None, tb: Any) -> None:
        import mlflow

        mlflow.end_run(status="FINISHED" if exc_type is None else "FAILED")
        if self.run_id is not None:
            (_STATE_DIR / f"run-{self.run_id}.json").unlink(missing_ok=True)
        if self._saved_env is None:
            os.environ.pop("MLFLOW_TRACKING_URI", None)
            mlflow.set_tracking_uri(None)
        else:
            os.environ["MLFLOW_TRACKING_URI"] = self._saved_env


# Runs left RUNNING by a killed process: markers of open runs and their owners.


def _proc_stat(pid: int) -> list[str] | None:
    """Fields of ``/proc/<pid>/stat`` after the command name (state first), None when not readable."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None


def _start_ticks(pid: int) -> str | None:
    """Start time of process ``pid`` in clock ticks since boot (Linux ``/proc``), None when unknown or gone."""
    stat = _proc_stat(pid)
    return stat[19] if stat else None


def process_identity(pid: int | None = None) -> dict[str, Any]:
    """Who owns an open run: pid, host, and start time of the process (``pid``; default this one)."""
    pid = os.getpid() if pid is None else pid
    return {"pid": pid, "host": socket.gethostname(), "started": _start_ticks(pid)}


def owner_alive(owner: Mapping[str, Any]) -> bool:
    """Whether the process that ``owner`` (:func:`process_identity`) names still runs.

    A process on another host cannot be checked and counts as alive; a pid now held by a process
    that started at another time (pid reuse) counts as gone.
    """
    if owner.get("host") != socket.gethostname() or "pid" not in owner:
        return True
    try:
        os.kill(int(owner["pid"]), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    stat = _proc_stat(int(owner["pid"]))
    if stat is None:  # no /proc: the pid exists, which is all that can be known
        return True
    if stat[0] in ("Z", "X"):  # killed, not yet reaped by its parent
        return False
    return owner.get("started") is None or stat[19] == owner["started"]


def _write_run_marker(run_id: str) -> None:
    """Leave a marker naming this process as the owner of the open stage run ``run_id``."""
    with _locked():
        marker = _STATE_DIR / f"run-{run_id}.json"
        marker.write_text(json.dumps({"run_id": run_id, **process_identity()}))


def stale_markers(state_dir: Path | None = None) -> list[tuple[Path, dict[str, Any]]]:
    """Markers of open runs (stage runs and invocations) whose owner process is gone."""
    state_dir = _STATE_DIR if state_dir is None else state_dir
    if not state_dir.is_dir():
        return []
    stale = []
    for marker in sorted([*state_dir.glob("run-*.json"), *state_dir.glob("invocation-*.json")]):
        try:
            data = json.loads(marker.read_text())
        except (OSError, ValueError):
            continue  # being written, or already removed by another process
        if "pid" in data and not owner_alive(data):
            stale.append((marker, data))
    return stale


def close_stale_runs() -> list[str]:
    """Close as KILLED the runs whose owner process died and remove their markers; return the run ids.

    Cheap when nothing is stale (a directory listing; MLflow is imported only when needed), so the
    Snakefile calls it on every start. The run's end time is the time it was found, also in the tag
    ``topoloc.killed``.
    """
    stale = stale_markers()
    if not stale:
        return []
    client = _client()
    found = time.time()
    closed = []
    for marker, data in stale:
        try:
            run = client.get_run(data["run_id"])
        except Exception:  # noqa: BLE001 (a run deleted from the store, or another store: nothing to close)
            run = None
        if run is not None and run.info.status == "RUNNING":
            when = time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime(found))
            client.set_tag(run.info.run_id, "topoloc.killed",
                           f"process {data['pid']} on {data['host']} gone; found at {when}")
            client.set_terminated(run.info.run_id, status="KILLED", end_time=int(found * 1000))
            closed.append(run.info.run_id)
        marker.unlink(missing_ok=True)
    return closed
