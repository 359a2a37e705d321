"""Localization from many starts beside the oracle, as the experiments run it: the figures of a group of starts, the
rows of one drive, and every localizer on the KITTI drives of a region's pipeline."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization import calibration
from topoloc.localization.evaluation import DriveTruth, Judge, score_start, start_frames, summarize
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.motion.poses import read_poses
from topoloc.registry import make, registry
from topoloc.trajectory.model import load_model

log = logging.getLogger(__name__)


def targets(group: pd.DataFrame) -> dict[str, float]:
    """The issue's figures on one group of starts of one localizer (columns of :func:`start_rows`); ``ece``: the
    expected calibration error of all the group's answers (:mod:`topoloc.localization.calibration`), resolved by
    the oracle or not."""
    resolved = group[np.isfinite(group.oracle_m)]
    unresolved = group[~np.isfinite(group.oracle_m)]
    after = resolved[np.isfinite(resolved.accuracy_after)]
    return {
        "starts": len(group), "resolved": len(resolved),
        "localized_share": float(np.isfinite(resolved.localized_m).mean()) if len(resolved) else np.nan,
        "median_ratio": float(np.median(resolved.ratio)) if len(resolved) else np.nan,
        "accuracy_after": float(np.average(after.accuracy_after, weights=after.steps)) if len(after) else np.nan,
        "position_error_m": float(np.nanmedian(resolved.position_error_m)) if resolved.position_error_m.notna().any() else np.nan,
        "confident_wrong_unresolved": float(np.average(unresolved.confident_wrong, weights=unresolved.steps))
        if len(unresolved) and unresolved.steps.sum() else np.nan,
        "confident_wrong_all": float(np.average(group.confident_wrong, weights=group.steps)) if group.steps.sum() else np.nan,
        "ece": calibration.ece(group) if calibration.COLUMNS[0] in group else np.nan,
    }


def confirmed(frame: pd.DataFrame, confirm_m: float) -> pd.DataFrame:
    """The starts whose drive goes on for at least ``confirm_m`` after the oracle's limit (elsewhere the oracle
    is unique "to the end of the drive" over less than ``confirm_m``, and so is a localizer judged)."""
    return frame[frame.length_m - frame.oracle_m >= confirm_m]


def confirmed_figures(group: pd.DataFrame, confirm_m: float) -> dict[str, float]:
    """The :func:`confirmed` starts the oracle resolves, and the localized share and median ratio on them."""
    c = targets(confirmed(group, confirm_m))
    return {"confirmed": c["resolved"], "localized_confirmed": c["localized_share"], "ratio_confirmed": c["median_ratio"]}


def with_confirmed(group: pd.DataFrame, confirm_m: float) -> dict[str, float]:
    """:func:`targets`, plus :func:`confirmed_figures`."""
    return {**targets(group), **confirmed_figures(group, confirm_m)}


def start_rows(judge: Judge, truth: DriveTruth, runs: list, limits: dict[int, float], ev: dict[str, Any],
               localizer: str, answers: list[pd.DataFrame] | None = None, **columns: Any) -> list[dict[str, Any]]:
    """One row per start of ``runs`` (``run_starts``' (start, observations, track)) of ``localizer``: the fixed
    ``columns``, the start, its scores, the oracle's limit and the ratio to it. With ``answers``, each start's
    answers are appended to it too: one frame per start, a row per answer (its ``confidence`` and whether it is
    ``right``), with the fixed ``columns`` and the start (the input of a recalibration,
    :func:`topoloc.localization.calibration.fit_logit_calibration`)."""
    rows = []
    for start, observations, track in runs:
        m = score_start(judge, truth, start, observations.frame, track.state, track.confidence, track.xy,
                        float(ev["confirm_m"]), float(ev["sure"]))
        if answers is not None and len(observations.frame):
            frame = np.asarray(observations.frame, np.int64)
            right = judge.right(track.state, truth.edge[frame], truth.xy[frame])
            answers.append(pd.DataFrame({**columns, "localizer": localizer, "start": start,
                                         "confidence": np.asarray(track.confidence, float), "right": right}))
        limit = limits[start]
        ratio = (m["localized_m"] / limit if np.isfinite(m["localized_m"]) else np.inf) if np.isfinite(limit) else np.nan
        rows.append({**columns, "start": start, "start_m": float(truth.driven[start]), "localizer": localizer, **m,
                     "oracle_m": limit, "ratio": ratio})
    return rows


def evaluate_kitti(results: Path, conf: dict, names: list[str], model_path: Path | None = None,
                   drives: tuple[str, ...] = ("gt", "orbslam2")) -> tuple[pd.DataFrame, pd.DataFrame, dict, RoadMap]:
    """Every localizer of ``names`` from a start every ``localization.evaluate.start_every_m`` of each drive of the
    pipeline's ``results`` folder, beside the oracle: the per-start table, its summary (with ``cpu_s``), the CPU
    seconds and the road map."""
    lconf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    ev = conf["localization"]["evaluate"]
    graph = RoadGraph.load(results / "graph" / "graph.graphml")
    known = registry()
    model = load_model(str(model_path)) if any(known[n].requires_model for n in names) else None
    road = RoadMap(graph, conf["localization"]["decode"]["u_turns"], conf["localization"]["decode"]["max_skip_m"], model)
    oracle = Oracle(graph, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
    judge = Judge(graph, ev["node_tolerance_m"])
    rows, seconds = [], {}
    for drive in drives:
        frames = pd.read_csv(results / "odometry" / drive / "frames.csv")
        truth = DriveTruth.from_frames(frames)
        odometry = Odometry.from_poses(read_poses(results / "odometry" / drive / "poses.txt"))
        starts = start_frames(truth.driven, ev["start_every_m"])
        path = true_path(graph, truth.edge, truth.xy, truth.driven)
        began = time.process_time()
        limits = {int(s): oracle.count(path, int(s), ev["confirm_m"]).localized_m for s in starts}
        seconds[(drive, "oracle")] = time.process_time() - began
        for start, limit in limits.items():
            rows.append({"drive": drive, "start": start, "localizer": "oracle", "steps": 1.0, "localized_m": limit,
                         "accuracy_after": np.nan, "position_error_m": np.nan, "confident_wrong": np.nan,
                         "oracle_m": limit, "ratio": 1.0 if np.isfinite(limit) else np.nan})
        for name in names:
            localizer = make(name)
            localizer.reset(road, lconf)  # map structures: built once, outside the timing
            began = time.process_time()
            runs = localizer.run_starts(odometry, road, lconf, starts)
            seconds[(drive, name)] = time.process_time() - began
            for start, observations, track in runs:
                m = score_start(judge, truth, start, observations.frame, track.state, track.confidence, track.xy,
                                ev["confirm_m"], ev["sure"])
                limit = limits[start]
                ratio = (m["localized_m"] / limit if np.isfinite(m["localized_m"]) else np.inf) if np.isfinite(limit) else np.nan
                rows.append({"drive": drive, "start": start, "localizer": name, **m, "oracle_m": limit, "ratio": ratio})
            log.info("%s %s: %d starts, %.2f s CPU", drive, name, len(runs), seconds[(drive, name)])
    table = pd.DataFrame(rows)
    summary = summarize(table)
    summary["cpu_s"] = [seconds.get((r.drive, r.localizer), np.nan) for r in summary.itertuples()]
    return table, summary, seconds, road
