"""Experiment ``simulated``: localizers beside the oracle on many simulated drives of several maps, one job per noise
level (rule ``localize_simulated``), and their summary over the levels (rule ``summarize_simulated``).

Per map and level (:data:`topoloc.odometry.simulate.NOISE_LEVELS`): ``drives`` random drives of 0.5-4 km, a
circuit driven twice and a drive with a long stop and a reversing stretch, drawn from the seed
``[seed, map's place in maps, level's place in levels]``. Every localizer runs from a start every ``start_every_m``
(:mod:`topoloc.localization.evaluation`) beside the oracle.
"""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.experiments.many_starts import start_rows, targets
from topoloc.experiments.maps import load_map
from topoloc.experiments.summary import write_summary
from topoloc.io import write_json, write_text
from topoloc.localization import calibration
from topoloc.localization.evaluation import DriveTruth, Judge, start_frames
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.plot import plot_reliability
from topoloc.localization.roadmap import RoadMap
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make, registry
from topoloc.trajectory.model import load_model

log = logging.getLogger(__name__)

#: The figures of :func:`topoloc.experiments.many_starts.targets` in the summary.
FIGURES = ["localized_share", "median_ratio", "accuracy_after", "position_error_m", "confident_wrong_unresolved", "ece"]


def drive_plan(drives: int, rng: np.random.Generator) -> list[tuple[str, float]]:
    """(pattern, length) of the drives of one map and level: random 0.5-4 km, a circuit, a stop-and-reverse."""
    lengths = np.exp(rng.uniform(np.log(500.0), np.log(4000.0), drives))
    return [("random", float(x)) for x in lengths] + [("circuit", 1600.0), ("stop_reverse", 1500.0)]


def localize_level(conf: dict[str, Any], level: str, models: dict[str, str],
                   scratch: Path) -> tuple[pd.DataFrame, dict[str, float]]:
    """Every map's drives at one noise ``level``: the per-start table and the CPU seconds of each localizer."""
    exp = conf["simulated"]
    loc_conf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    ev = conf["localization"]["evaluate"]
    level_index = list(exp["levels"]).index(level)
    rows, seconds = [], {name: 0.0 for name in exp["localizers"]}
    for map_index, map_name in enumerate(exp["maps"]):
        graph = load_map(map_name, conf["graph"], exp["kitti00_osm"], scratch)
        model = load_model(models[map_name]) if map_name in models else None
        road = RoadMap(graph, conf["localization"]["decode"]["u_turns"], model=model)
        oracle = Oracle(graph, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
        judge = Judge(graph, ev["node_tolerance_m"])
        localizers = {name: make(name) for name in exp["localizers"]
                      if model is not None or not registry()[name].requires_model}
        rng = np.random.default_rng([int(exp["seed"]), map_index, level_index])
        for drive_index, (pattern, length) in enumerate(drive_plan(int(exp["drives"]), rng)):
            sim = simulate_pattern_drive(graph, length, NOISE_LEVELS[level], rng, pattern)
            truth = DriveTruth(sim.edge, sim.gt_xy, np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(sim.gt_xy, axis=0).T))]))
            path = true_path(graph, truth.edge, truth.xy, truth.driven)
            odometry = sim.odometry
            starts = start_frames(truth.driven, float(exp["start_every_m"]))
            limits = {s: oracle.count(path, int(s), float(ev["confirm_m"])).localized_m for s in starts}
            drive = f"{map_name}/{level}/{drive_index:02d}-{pattern}"
            for name, localizer in localizers.items():
                began = time.process_time()
                runs = localizer.run_starts(odometry, road, loc_conf, starts)
                seconds[name] += time.process_time() - began
                rows += start_rows(judge, truth, runs, limits, ev, name, map=map_name, level=level, pattern=pattern,
                                   drive=drive)
            log.info("%s: %.0f m, %d starts, noise %s", drive, sim.length_m, len(starts),
                     ", ".join(f"{k} {v:.3g}" for k, v in sim.noise.items()))
    return pd.DataFrame(rows), seconds


def report(frame: pd.DataFrame, seconds: dict[str, float]) -> str:
    """Markdown tables of :func:`targets` per map and level, per pattern, and overall; the CPU; the metric filter's
    targets."""
    def table(by: list[str]) -> str:
        rows = [{**dict(zip(by, key if isinstance(key, tuple) else (key,))), **targets(group)}
                for key, group in frame.groupby(by, sort=False)]
        return pd.DataFrame(rows).to_markdown(index=False, floatfmt=".3f") + "\n"
    parts = ["## Per map and noise level\n", table(["localizer", "map", "level"]),
             "## Per pattern\n", table(["localizer", "pattern"]),
             "## Overall\n", table(["localizer"]),
             "CPU seconds of the localizers (all starts): " + ", ".join(f"{k} {v:.1f}" for k, v in seconds.items())]
    metric = frame[frame.localizer == "metric"]
    if len(metric):
        t = targets(metric)
        parts += ["\n## Targets of the metric filter\n",
                  f"- localizes >= 95 % of the oracle-resolved starts: {t['localized_share']:.3f}\n"
                  f"- median ratio to the oracle <= 1.3: {t['median_ratio']:.3f}\n"
                  f"- right on >= 97 % of the later steps: {t['accuracy_after']:.3f}\n"
                  f"- confident wrong answers where the oracle does not resolve the start <= 2 %: "
                  f"{t['confident_wrong_unresolved']:.4f}\n"
                  f"- expected calibration error of all answers <= 0.03: {t['ece']:.4f}"]
    return "\n".join(parts) + "\n"


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """One noise level (``conf['level']``): ``starts`` (per-start CSV), ``figures`` (markdown), ``metrics`` (JSON:
    the targets of each localizer and its CPU seconds)."""
    models = {name.removeprefix("model_"): path for name, path in inputs.items() if name.startswith("model_")}
    with tempfile.TemporaryDirectory() as scratch:
        frame, seconds = localize_level(conf, str(conf["level"]), models, Path(scratch))
    starts = Path(outputs["starts"])
    starts.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(starts, index=False)
    write_text(outputs["figures"], report(frame, seconds))
    metrics = {f"{name}/{key}": value for name, group in frame.groupby("localizer", sort=False)
               for key, value in targets(group).items()}
    metrics |= {f"{name}/cpu_s": value for name, value in seconds.items()}
    metrics = {k: float(v) for k, v in metrics.items() if np.isfinite(v)}
    write_json(outputs["metrics"], metrics)
    return metrics


def summarize(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """``summary`` (markdown) and ``json``: per localizer and level the targets, and their mean and spread over the
    levels (inputs ``starts_<level>``); ``reliability``: the reliability diagram of each localizer's answers over
    every level."""
    exp = conf["simulated"]
    jobs, frames = [], []
    for level in exp["levels"]:
        frame = pd.read_csv(inputs[f"starts_{level}"])
        frames.append(frame)
        jobs += [{"localizer": name, "level": level, **targets(group)} for name, group in frame.groupby("localizer", sort=False)]
    pooled = pd.concat(frames, ignore_index=True)
    plot_reliability(calibration.reliability_per(pooled), outputs["reliability"],
                     f"Simulated drives, noise {', '.join(exp['levels'])}: reliability of the answers' confidence, "
                     f"{len(pooled.drop_duplicates(['localizer', 'drive', 'start']))} starts")
    jobs = pd.DataFrame(jobs).sort_values("localizer", kind="stable")
    sentence = (f"Localizers beside the oracle on simulated drives of {', '.join(exp['maps'])}: per map and noise level "
                f"{exp['drives']} random drives of 0.5-4 km, a circuit driven twice and a stop-and-reverse drive "
                f"(seed {exp['seed']}), a start every {exp['start_every_m']:g} m; figures of the oracle-resolved "
                f"starts per level, then their mean and sample standard deviation over the levels; ece: the expected "
                f"calibration error of all answers (reliability.png: every level pooled).")
    write_summary(outputs, "Simulated drives: localizers against the oracle", sentence, jobs, "level", ["localizer"],
                  FIGURES)
    metrics = {f"{r.localizer}/{f}_mean": float(getattr(r, f)) for r in jobs.groupby("localizer").mean(numeric_only=True)
               .reset_index().itertuples() for f in FIGURES if np.isfinite(getattr(r, f))}
    pooled_ece = {f"{name}/ece_all_levels": calibration.ece(group) for name, group in pooled.groupby("localizer", sort=False)}
    return metrics | {k: float(v) for k, v in pooled_ece.items() if np.isfinite(v)}
