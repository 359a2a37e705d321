"""Scaling benchmark of a multi-region run: wall time with 1, 2 and 4 local cores and through a one-node Slurm,
and the same config once more while another job loads the CPU (its tables must be identical).

    python -m benchmarks.bench_regions [--configfile config/multi_region/two_regions_quick.yaml]
        [--runs cores1,cores2,loaded2,cores4,slurm] [--root /tmp/topoloc-bench-regions] [--target all]

Each run is ``snakemake TARGET --configfile CONFIG`` in its own fresh clone of this repository's HEAD (commit
first: uncommitted changes are not in the clone) under ``--root``, beside a link to ``../shared``:

- ``coresN``: ``--cores N``;
- ``loadedN``: ``--cores N`` while N busy processes (a tight Python loop each, at the same priority) compete for
  the CPU the whole time;
- ``slurm``: through ``profiles/slurm`` on a one-node Slurm on localhost (``cluster/slurm_local.sh``; root,
  ``slurm-wlm``, ``munge`` and the ``[cluster]`` extra), ``--jobs 4``; every job must have gone through
  sbatch (the cluster's job completion log).

Prints one row per run: wall time, jobs run, and how many of the evaluation tables (held-out accuracy,
localization from many starts, teach and repeat, the cross-region summary) are byte-identical to those of the
first run; a differing table is named. Rows also go to ``--root``/runs.csv as each run ends.
"""

from __future__ import annotations

import argparse
import hashlib
import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from benchmarks.markdown import add_out_option, markdown_copy

REPO = Path(__file__).resolve().parents[1]
#: The tables compared between runs (globs under results/).
TABLES = ["*/evaluation/accuracy.csv", "*/localization/localization.csv", "*/localization/starts.csv",
          "*/teach_repeat/summary.csv", "regions/summary.csv"]


def busy() -> None:
    """Load one core until killed."""
    x = 0
    while True:
        x = (x * 7 + 1) % 1000003


def clone(root: Path, label: str) -> Path:
    """A fresh clone of HEAD in ``root/label/topoloc``, with ``../shared`` linked beside it."""
    folder = root / label
    if folder.exists():
        subprocess.run(["rm", "-rf", str(folder)], check=True)
    folder.mkdir(parents=True)
    shared = REPO.parent / "shared"
    if shared.is_dir():
        (folder / "shared").symlink_to(shared)
    subprocess.run(["git", "clone", "--quiet", str(REPO), str(folder / "topoloc")], check=True)
    return folder / "topoloc"


def tables(results: Path) -> dict[str, str]:
    """sha256 of each compared table, by its path under results/."""
    found = {}
    for pattern in TABLES:
        for path in sorted(results.glob(pattern)):
            found[str(path.relative_to(results))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return found


def snakemake(checkout: Path, target: str, config: str, extra: list[str], env: dict[str, str]) -> float:
    """Run the workflow; its wall time in seconds. Exits with the tail of its log when it fails."""
    env = {k: v for k, v in env.items() if k not in {"MLFLOW_TRACKING_URI", "TOPOLOC_INVOCATION_ID"}}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(checkout / "src"), env.get("PYTHONPATH")]))  # the clone's code
    log = checkout / "bench_regions.log"
    began = time.perf_counter()
    with log.open("w") as out:
        proc = subprocess.run([sys.executable, "-m", "snakemake", target, "--configfile", config, *extra],
                              cwd=checkout, stdout=out, stderr=subprocess.STDOUT, env=env, check=False)
    wall = time.perf_counter() - began
    if proc.returncode:
        raise SystemExit(f"bench_regions: snakemake failed in {checkout} (log: {log}):\n"
                         + "\n".join(log.read_text().splitlines()[-15:]))
    return wall


def run_slurm(checkout: Path, target: str, config: str) -> tuple[float, int]:
    """The workflow through a fresh one-node Slurm: wall time and the number of jobs Slurm completed."""
    folder = checkout.parent / "slurm"
    script = REPO / "cluster" / "slurm_local.sh"
    started = subprocess.run(["bash", str(script), "start", str(folder)], capture_output=True, text=True, check=False)
    if started.returncode:
        raise SystemExit(f"bench_regions: cannot start Slurm: {started.stderr.strip()}")
    try:
        env = {**os.environ, "SLURM_CONF": started.stdout.strip().removeprefix("export SLURM_CONF=")}
        wall = snakemake(checkout, target, config,
                         ["--profile", str(checkout / "profiles" / "slurm"), "--slurm-no-account", "--jobs", "4",
                          "--slurm-status-command", "squeue", "--slurm-init-seconds-before-status-checks", "1"], env)
        completed = sum("JobState=COMPLETED" in line for line in (folder / "jobcomp.txt").read_text().splitlines())
    finally:
        subprocess.run(["bash", str(script), "stop", str(folder)], capture_output=True, check=False)
    return wall, completed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--configfile", default="config/multi_region/two_regions_quick.yaml")
    parser.add_argument("--runs", default="cores1,cores2,loaded2,cores4,slurm")
    parser.add_argument("--root", default="/tmp/topoloc-bench-regions")
    parser.add_argument("--target", default="all")
    add_out_option(parser, "bench_regions")
    args = parser.parse_args(argv)
    with markdown_copy(args.out):
        if subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO, capture_output=True,
                          text=True, check=True).stdout.strip():
            print("bench_regions: the work tree has uncommitted changes; the runs use HEAD without them", file=sys.stderr)
        root = Path(args.root)
        root.mkdir(parents=True, exist_ok=True)
        rows, reference = [], None
        for label in args.runs.split(","):
            checkout = clone(root, label)
            print(f"{label}: running in {checkout}", file=sys.stderr, flush=True)
            slurm_jobs = None
            if label == "slurm":
                wall, slurm_jobs = run_slurm(checkout, args.target, args.configfile)
            elif label.startswith(("cores", "loaded")):
                cores = int(label.removeprefix("cores").removeprefix("loaded"))
                hogs = [multiprocessing.Process(target=busy, daemon=True) for _ in range(cores if label.startswith("loaded") else 0)]
                for hog in hogs:
                    hog.start()
                try:
                    wall = snakemake(checkout, args.target, args.configfile, ["--cores", str(cores)], dict(os.environ))
                finally:
                    for hog in hogs:
                        hog.kill()
                        hog.join()
            else:
                raise SystemExit(f"bench_regions: run {label!r} is not coresN, loadedN or slurm")
            jobs = len(list((checkout / "results").glob("*/benchmarks/*.tsv")))
            found = tables(checkout / "results")
            reference = reference or (label, found)
            differ = sorted(k for k in set(found) | set(reference[1]) if reference[1].get(k) != found.get(k))
            rows.append({"run": label, "wall_s": round(wall, 1), "jobs": jobs,
                         "slurm_jobs_completed": slurm_jobs if slurm_jobs is not None else "",
                         f"tables equal to {reference[0]}": f"{len(set(found) | set(reference[1])) - len(differ)}/{len(reference[1])}",
                         "differing": " ".join(differ)})
            pd.DataFrame(rows).to_csv(root / "runs.csv", index=False)
            print(pd.DataFrame(rows).tail(1).to_markdown(index=False), file=sys.stderr, flush=True)
        print(f"## {args.configfile}: snakemake {args.target}\n")
        print(pd.DataFrame(rows).to_markdown(index=False))
        return 0


if __name__ == "__main__":
    sys.exit(main())
