"""Many parallel stage runs against one MLflow store: do they all arrive, and how long do they take?

Each of ``--jobs`` processes (``--parallel`` at a time) opens a :class:`topoloc.tracking.StageRun` under one
invocation (as the jobs of one ``snakemake --cores N`` call do), logs ``--params`` params, ``--metrics``
metric steps one call each (as Lightning's logger does) and one artifact, and closes it. The store is the
default SQLite file under a scratch ``results/`` (or ``MLFLOW_TRACKING_URI`` when set, e.g. the shared server).

    python -m benchmarks.bench_tracking_store --jobs 32 --parallel 8

Prints one line: jobs, runs recorded, failed jobs (with the first error), the store's journal mode, wall s.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sqlite3
import tempfile
import time
import traceback
from pathlib import Path

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc import tracking


def _job(args: tuple[str, str, int, int, int]) -> str | None:
    """One stage run; returns None, or the last line of the error."""
    workdir, invocation, index, params, metrics = args
    os.chdir(workdir)
    os.environ[tracking.INVOCATION_ENV] = invocation
    try:
        with tracking.StageRun("bench", f"job{index}", {"topoloc.wildcards.job": str(index)},
                               {"p": {f"k{k}": k for k in range(params)}}) as run:
            import mlflow

            for step in range(metrics):
                mlflow.log_metric("train/loss", 1.0 / (step + 1), step=step)
            artifact = Path(workdir) / f"artifact{index}.json"
            artifact.write_text(f'{{"job": {index}}}')
            run.log_artifact(artifact)
            run.log_metrics({"job": index})
    except Exception:  # noqa: BLE001 (counted and reported)
        return traceback.format_exc().strip().splitlines()[-1]
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=32)
    parser.add_argument("--parallel", type=int, default=8)
    parser.add_argument("--params", type=int, default=30)
    parser.add_argument("--metrics", type=int, default=20)
    add_out_option(parser, "bench_tracking_store")
    args = parser.parse_args()
    with markdown_copy(args.out):
        workdir = tempfile.mkdtemp(prefix="bench-tracking-")
        invocation = tracking.new_invocation_id()
        started = time.perf_counter()
        with multiprocessing.get_context("spawn").Pool(args.parallel) as pool:
            errors = pool.map(_job, [(workdir, invocation, i, args.params, args.metrics) for i in range(args.jobs)])
        seconds = time.perf_counter() - started
        os.chdir(workdir)
        from mlflow import MlflowClient

        client = MlflowClient(tracking.tracking_uri())
        experiment = client.get_experiment_by_name("bench")
        runs = client.search_runs([experiment.experiment_id], f"tags.`topoloc.invocation` = '{invocation}'",
                                  max_results=10000) if experiment else []
        complete = [r for r in runs if "job" in r.data.metrics and len(r.data.params) == args.params]
        tracking.finish_invocation(invocation, "FINISHED")
        db = Path(workdir) / "results" / "mlflow.db"
        journal = sqlite3.connect(db).execute("PRAGMA journal_mode").fetchone()[0] if db.exists() else "server"
        failed = [e for e in errors if e]
        print(f"jobs {args.jobs} (parallel {args.parallel}): runs recorded {len(complete)}/{args.jobs}, "
              f"failed {len(failed)}{' (' + failed[0] + ')' if failed else ''}, journal {journal}, wall {seconds:.1f} s")


if __name__ == "__main__":
    main()
