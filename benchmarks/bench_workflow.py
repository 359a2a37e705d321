"""Benchmark of the workflow backbone: dry run, no-op rerun, and the map stages.

Runs in a scratch copy of the repository (results and MLflow store start
empty) and prints a markdown table. Usage::

    python -m benchmarks.bench_workflow [--configfile config/regions/kitti00.yaml] [--repeats 3]

Targets (issue 2): ``snakemake -n all`` and a no-op rerun at most 5 s each;
``download_osm`` + ``build_graph`` on Helsinki at most 20 s.
"""

from __future__ import annotations

import argparse
import csv
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.markdown import add_out_option, markdown_copy

REPO = Path(__file__).resolve().parents[1]


def snakemake(root: Path, *args: str) -> float:
    """Seconds taken by ``snakemake ARGS`` in ``root`` (fails loudly)."""
    started = time.perf_counter()
    subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=root, check=True, capture_output=True)
    return time.perf_counter() - started


def rule_seconds(root: Path, region: str, rule: str) -> float:
    """Wall seconds of one rule from its Snakemake benchmark file."""
    with open(root / "results" / region / "benchmarks" / f"{rule}.tsv") as handle:
        return float(next(csv.DictReader(handle, delimiter="\t"))["s"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configfile", default=None, help="extra config file (relative to the repository)")
    parser.add_argument("--repeats", type=int, default=3, help="repeats of the dry run and no-op rerun")
    add_out_option(parser, "bench_workflow")
    args = parser.parse_args()
    with markdown_copy(args.out):
        extra = ["--configfile", str(REPO / args.configfile)] if args.configfile else []
        with tempfile.TemporaryDirectory() as tmp:
            root = Path(tmp) / "repo"
            root.mkdir()
            shutil.copy(REPO / "Snakefile", root)
            for folder in ("workflow", "config", "src"):
                shutil.copytree(REPO / folder, root / folder, ignore=shutil.ignore_patterns("__pycache__"))
            if args.configfile and (REPO.parent / "shared").exists():
                (Path(tmp) / "shared").symlink_to(REPO.parent / "shared")
            dry_cold = snakemake(root, "-n", "all", *extra)
            full = snakemake(root, "all", "--cores", "2", *extra)
            region = next(p.name for p in (root / "results").iterdir() if p.is_dir() and not p.name.startswith((".", "ml", "osmnx")))
            stages = {rule: rule_seconds(root, region, rule) for rule in ("download_osm", "build_graph")}
            dry = [snakemake(root, "-n", "all", *extra) for _ in range(args.repeats)]
            noop = [snakemake(root, "all", "--cores", "2", *extra) for _ in range(args.repeats)]
        rows = [
            ("`snakemake -n all` (empty results)", dry_cold, "<= 5"),
            (f"`snakemake -n all` (up to date, median of {args.repeats})", statistics.median(dry), "<= 5"),
            (f"no-op rerun `snakemake all` (median of {args.repeats})", statistics.median(noop), "<= 5"),
            ("download_osm (benchmark file)", stages["download_osm"], ""),
            ("build_graph (benchmark file)", stages["build_graph"], ""),
            ("download_osm + build_graph", sum(stages.values()), "<= 20" if region == "helsinki" else ""),
            ("whole `snakemake all --cores 2` (cold, incl. MLflow store creation)", full, ""),
        ]
        print(f"region: {region}\n")
        print("| what | seconds | target |\n|---|---:|---|")
        for what, seconds, target in rows:
            print(f"| {what} | {seconds:.2f} | {target} |")


if __name__ == "__main__":
    main()
