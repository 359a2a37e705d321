"""Every real drive in one run: KITTI 00, 02 and 10, localized from many starts, one table over all drives.

    python -m benchmarks.bench_real_drives [--cores 2] [--configfile config/multi_region/real_drives.yaml]

Runs ``snakemake results/regions/summary.md --configfile config/regions/kitti00.yaml CONFIG`` in this checkout
(results under ``results/``; what is up to date is not rerun): per region the map, each drive's odometry (the
ground truth, 00's ORB-SLAM2 poses, and the ground truth with stereo-VO-level noise, ``vo_noise``), the
localizers from a start every ``localization.evaluate.start_every_m`` and the evaluation beside the oracle; then
the cross-region summary. Prints, per drive, the odometry's KITTI errors against the ground truth, then per
region, drive and localizer: the starts, the oracle's resolved share, the localized share (of all starts and of
those the oracle resolves), the median ratio to the oracle, the position error, the confident-wrong share and
the expected calibration error (ECE), against the issue's targets (confident wrong <= 0.5 %, ECE <= 0.03,
localized >= the oracle's share minus 2 points, median ratio <= 1.0, position error <= 3 m).

The real drives are a check: report them, never tune a parameter to them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from benchmarks.markdown import add_out_option, markdown_copy

REPO = Path(__file__).resolve().parents[1]
BASE = "config/regions/kitti00.yaml"


def run_snakemake(config: str, cores: int) -> float:
    """The run up to the cross-region summary; its wall time. Exits with the tail of its log when it fails."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")]))}
    log = REPO / "results" / "benchmarks" / "bench_real_drives.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    began = time.perf_counter()
    with log.open("w") as out:
        proc = subprocess.run([sys.executable, "-m", "snakemake", "results/regions/summary.md", "--cores", str(cores),
                               "--configfile", BASE, config], cwd=REPO, stdout=out, stderr=subprocess.STDOUT, env=env, check=False)
    if proc.returncode:
        raise SystemExit(f"bench_real_drives: snakemake failed (log: {log}):\n" + "\n".join(log.read_text().splitlines()[-15:]))
    return time.perf_counter() - began


def odometry_table(results: Path, regions: list[str]) -> pd.DataFrame:
    """Per drive: km, and the KITTI errors of its odometry against the ground truth (``extract_odometry``)."""
    rows = []
    for region in regions:
        for path in sorted((results / region / "odometry").glob("*/odometry.json")):
            stats = json.loads(path.read_text())
            ev = stats.get("evaluation", {})
            rows.append({"region": region, "drive": path.parent.name, "km": round(ev.get("gt_length_m", stats["length_m"]) / 1000, 2),
                         "t_err %": round(ev.get("t_err_pct", float("nan")), 2),
                         "r_err deg/100 m": round(ev.get("r_err_deg_per_100m", float("nan")), 3),
                         "ATE m": round(ev.get("ate_m", float("nan")), 1)})
    return pd.DataFrame(rows)


def drive_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Per region, drive and localizer (not the oracle, not the ``all`` rows): the figures of the targets."""
    rows = []
    for r in summary[(summary.localizer != "oracle") & (summary.drive != "all")].itertuples(index=False):
        rows.append({"region": r.region, "drive": r.drive, "localizer": r.localizer, "starts": int(r.starts),
                     "oracle resolves": f"{100 * r.oracle_resolved:.1f} %", "localized": f"{100 * r.localized_share:.1f} %",
                     "localized where resolved": f"{100 * r.localized_where_resolved:.1f} %",
                     "median ratio": f"{r.median_ratio:.2f}", "position error m": f"{r.position_error_m:.1f}",
                     "confident wrong": f"{100 * r.confident_wrong:.2f} %", "ECE": f"{r.ece:.3f}"})
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--configfile", default="config/multi_region/real_drives.yaml")
    parser.add_argument("--cores", type=int, default=2)
    add_out_option(parser, "bench_real_drives")
    args = parser.parse_args(argv)
    with markdown_copy(args.out):
        wall = run_snakemake(args.configfile, args.cores)
        results = REPO / "results"
        summary = pd.read_csv(results / "regions" / "summary.csv")
        regions = list(dict.fromkeys(summary.region))
        print(f"## All real drives: snakemake results/regions/summary.md --configfile {BASE} {args.configfile}\n")
        print(f"Wall time {wall:.0f} s with {args.cores} cores (what was up to date was not rerun).\n")
        print("### Odometry of each drive against its ground truth\n")
        print(odometry_table(results, regions).to_markdown(index=False) + "\n")
        print("### Localization from many starts\n")
        print("Targets: confident wrong <= 0.5 %, ECE <= 0.03, localized >= oracle resolves - 2 points, median ratio "
              "<= 1.0, position error <= 3 m.\n")
        print(drive_table(summary).to_markdown(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
