"""Experiment ``map_errors``: localizers beside the oracle on drives simulated on a true road network and localized on
a map with errors, one job per error type over its levels (rule ``localize_map_errors``; the job ``none`` is the map
equal to the truth), and their summary (rule ``summarize_map_errors``).

The work is :mod:`topoloc.experiments.map_error_starts` (maps, drives, ground truth on the map, the figures); error
types and levels are :mod:`topoloc.odometry.map_errors`.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.experiments.map_error_starts import CONFIRMED, FIGURES, UP_TO_MEDIUM, figures, level_table, localize_error, report
from topoloc.experiments.summary import write_summary
from topoloc.io import write_json, write_text
from topoloc.localization import calibration
from topoloc.localization.plot import plot_reliability


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """One error type (``conf['error']``) at every level of ``map_errors.levels`` (only ``none`` for ``none``):
    ``starts`` (per-start CSV), ``figures`` (markdown), ``metrics`` (JSON: per level and localizer the figures, and
    the CPU seconds)."""
    error = str(conf["error"])
    levels = ["none"] if error == "none" else list(conf["map_errors"]["levels"])
    with tempfile.TemporaryDirectory() as scratch:
        frame, seconds = localize_error(conf, error, levels, inputs, Path(scratch))
    starts = Path(outputs["starts"])
    starts.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(starts, index=False)
    write_text(outputs["figures"], report(frame, seconds))
    metrics = {f"{level}/{name}/{key}": value for (level, name), group in frame.groupby(["level", "localizer"], sort=False)
               for key, value in figures(group).items()}
    metrics |= {f"{name}/cpu_s": value for name, value in seconds.items()}
    metrics = {k: float(v) for k, v in metrics.items() if np.isfinite(v)}
    write_json(outputs["metrics"], metrics)
    return metrics


def summary_jobs(frames: list[pd.DataFrame]) -> pd.DataFrame:
    """One row per error type, level and localizer with its :func:`figures`."""
    rows = [{"error": error, "level": level, "localizer": name, **figures(group)}
            for frame in frames for (error, level, name), group in frame.groupby(["error", "level", "localizer"], sort=False)]
    return pd.DataFrame(rows)


def plot_calibration(frames: list[pd.DataFrame], path: str | Path,
                     levels: tuple[str, ...] = UP_TO_MEDIUM) -> dict[str, float]:
    """The reliability diagram of each localizer's answers, every error type and map pooled, at ``levels`` (by
    default those of the calibration target, :data:`UP_TO_MEDIUM`), to ``path``; their ECE per localizer."""
    pooled = pd.concat(frames, ignore_index=True)
    pooled = pooled[pooled.level.isin(levels)]
    if pooled.empty:
        raise ValueError(f"no starts at the levels {', '.join(levels)} to plot the reliability of")
    plot_reliability(calibration.reliability_per(pooled), path,
                     f"Map errors ({', '.join(sorted(set(pooled.error)))}), levels "
                     f"{', '.join(level for level in levels if level in set(pooled.level))}: reliability "
                     f"of the answers' confidence, {len(pooled.drop_duplicates(['localizer', 'drive', 'start']))} starts")
    return {str(name): calibration.ece(group) for name, group in pooled.groupby("localizer", sort=False)}


def summarize(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """``summary`` (markdown), ``json`` and ``reliability`` (figure, :func:`plot_calibration`): per localizer and
    error type the figures at each level (inputs ``starts_<error>``), beside the oracle of the map the localizer
    sees."""
    exp = conf["map_errors"]
    frames = [pd.read_csv(inputs[key]) for key in sorted(inputs) if key.startswith("starts_")]
    jobs = summary_jobs(frames)
    jobs["job"] = jobs.error + "/" + jobs.level
    jobs = jobs.sort_values("localizer", kind="stable")
    sentence = (f"Drives simulated on a true road network, localized on a map with errors (topoloc.odometry.map_errors) "
                f"of {', '.join(exp['maps'])}: per map, error type and level {exp['drives']} random drives of 1-3 km, "
                f"an out-and-back with U-turns, a block circled twice and a long straight (on dual_grid two mirror "
                f"walks), odometry noise {exp['noise']} (seed {exp['seed']}), a start every {exp['start_every_m']:g} m. "
                f"Judged on the map: the true position projected onto the map road it is mapped as (off-map where the "
                f"map lacks the road); the oracle is that of the map. oracle_resolved: share of starts the oracle "
                f"resolves; the localizer's figures are on those starts (localized_share: the share of them "
                f"localized); confident_wrong_all: wrong answers with confidence >= sure, of all answers; ece: the "
                f"expected calibration error of all answers (reliability.png: every error type up to medium pooled).")
    write_summary(outputs, "Map errors: localizers against the oracle of the map they see", sentence,
                  jobs[["localizer", "job", *FIGURES]], "job", ["localizer"], FIGURES)
    pooled_ece = plot_calibration(frames, outputs["reliability"])
    medium = jobs[jobs.level.isin(["medium", "none"])]
    metrics = {f"{r.localizer}/{r.error}/{r.level}/{f}": float(getattr(r, f)) for r in medium.itertuples()
               for f in FIGURES if np.isfinite(getattr(r, f))}
    levels = level_table(pd.concat(frames, ignore_index=True), float(conf["confirm_m"]))  # the targets are per level
    metrics |= {f"{r.localizer}/all_errors/{r.level}/{f}": float(getattr(r, f)) for r in levels.itertuples()
                for f in [*FIGURES, *CONFIRMED] if np.isfinite(getattr(r, f))}
    return metrics | {f"{name}/up_to_medium/ece": value for name, value in pooled_ece.items() if np.isfinite(value)}
