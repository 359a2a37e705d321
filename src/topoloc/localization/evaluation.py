"""Evaluation from many starts: every localizer, and the oracle, on a drive cut at start points.

A drive is cut at a start every ``start_every_m`` metres driven; from each start a localizer sees
only the drive from there on (:meth:`topoloc.motion.poses.Odometry.cut`). Its answers are
scored against the truth of the frames they were given at:

* an answer is *right* when it is the true road, or a road that meets the true one at a node the
  vehicle is within ``node_tolerance_m`` of (where the label switches, either road is where the
  vehicle is); where the vehicle is on no road of the map (true road -1), only "no road" is right;
* ``localized_m``: metres driven from the start to the first answer that starts a stretch of right
  answers lasting ``confirm_m`` (or to the end of the drive); NaN if never;
* ``accuracy_after``: share of right answers from there on; ``position_error_m``: the median distance
  of the answer's map position to the true position from there on (localizers with a position);
* ``confident_wrong``: share of all answers from the start that are wrong with a confidence of at
  least ``sure`` (a confident wrong answer is what a user must never see);
* ``cal_*``: the answers' confidence-bin sums (:mod:`topoloc.localization.calibration`), from which the
  reliability diagram and the expected calibration error (``ece``) of many starts follow;
* ``oracle_m``: the uniqueness limit of the map for the same start (:mod:`topoloc.localization.oracle`),
  and ``ratio`` = ``localized_m / oracle_m``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.localization import calibration


def read_frames(path: str) -> pd.DataFrame:
    """A ``frames.csv`` of ``extract_odometry``; InputError if it is not one."""
    try:
        frames = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as err:
        raise InputError(path, f"cannot read the frames table ({err})") from err
    missing = {"edge_id", "x", "y"} - set(frames.columns)
    if missing:
        raise InputError(path, f"not a frames table of extract_odometry (no {sorted(missing)[0]!r} column)")
    if len(frames) < 2:
        raise InputError(path, "empty trajectory: a drive needs at least two frames")
    return frames


@dataclass(frozen=True)
class DriveTruth:
    """Per frame of a drive: the true road, the true map position and the metres driven (ground truth)."""

    edge: NDArray[np.int64]
    xy: NDArray[np.float64]
    driven: NDArray[np.float64]

    @classmethod
    def from_frames(cls, frames: pd.DataFrame) -> DriveTruth:
        """From a ``frames.csv`` of ``extract_odometry`` (ground-truth positions where present, else the estimate)."""
        has_gt = {"gt_x", "gt_y"} <= set(frames.columns) and frames[["gt_x", "gt_y"]].notna().all().all()
        xy = frames[["gt_x", "gt_y"] if has_gt else ["x", "y"]].to_numpy(float)
        driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        return cls(frames["edge_id"].to_numpy(np.int64), xy, driven)


def localized_step(correct: NDArray[np.bool_], distance: NDArray[np.float64], confirm_m: float) -> int | None:
    """First step that starts a run of right answers lasting ``confirm_m`` metres or to the end; None if none."""
    correct = np.asarray(correct, bool)
    n = len(correct)
    # end of the run of right answers that contains each step (exclusive)
    run_end = np.empty(n, np.int64)
    end = n
    for t in range(n - 1, -1, -1):
        if not correct[t]:
            end = t
        run_end[t] = end
    for t in np.flatnonzero(correct):
        last = run_end[t] - 1
        if run_end[t] == n or distance[last] - distance[t] >= confirm_m:
            return int(t)
    return None


def start_frames(driven: NDArray[np.float64], every_m: float) -> NDArray[np.int64]:
    """Frames at 0, ``every_m``, ``2 every_m``, ... metres driven (each start at most once)."""
    marks = np.arange(0.0, float(driven[-1]) if len(driven) else 0.0, float(every_m))
    return np.unique(np.searchsorted(driven, marks)).astype(np.int64)


class Judge:
    """Scores answers against a drive's truth on one road graph (see the module docstring)."""

    def __init__(self, graph: RoadGraph, node_tolerance_m: float, node_xy: pd.DataFrame | None = None) -> None:
        """``node_xy``: where the nodes are in the truth's frame (columns ``x``, ``y``, indexed by node id), for a map
        whose nodes are displaced from the true junctions; default the graph's own."""
        self.u = graph.edges.u.to_numpy(np.int64)
        self.v = graph.edges.v.to_numpy(np.int64)
        self.node_xy = graph.nodes[["x", "y"]] if node_xy is None else node_xy[["x", "y"]]
        self.tolerance = float(node_tolerance_m)

    def right(self, answer: NDArray[np.int64], truth: NDArray[np.int64], xy: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Per answer: the true road, or a road meeting it at a node within the tolerance of ``xy``; where the truth is
        off the map (road -1, :func:`topoloc.odometry.map_error_drives.map_truth`), no road (an answer < 0)."""
        answer, truth = np.asarray(answer, np.int64), np.asarray(truth, np.int64)
        right = (answer == truth) | ((truth < 0) & (answer < 0))
        near = ~right & (answer >= 0) & (truth >= 0)
        if near.any() and self.tolerance > 0:
            idx = np.flatnonzero(near)
            a, t = answer[idx], truth[idx]
            for end_a in (self.u[a], self.v[a]):
                shared = (end_a == self.u[t]) | (end_a == self.v[t])
                node = self.node_xy.loc[end_a].to_numpy(float)
                close = np.hypot(*(node - xy[idx]).T) <= self.tolerance
                right[idx[shared & close]] = True
        return right


def score_start(judge: Judge, truth: DriveTruth, start: int, frame: NDArray[np.int64], state: NDArray[np.int64],
                confidence: NDArray[np.float64], xy: NDArray[np.float64] | None, confirm_m: float, sure: float) -> dict[str, float]:
    """Metrics of one localizer from one start; ``frame`` holds the absolute frame of each answer."""
    frame = np.asarray(frame, np.int64)
    driven = truth.driven[frame] - truth.driven[start]
    if len(frame) == 0:
        return {"steps": 0.0, "length_m": 0.0, "localized_m": np.nan, "accuracy_after": np.nan,
                "position_error_m": np.nan, "confident_wrong": 0.0, **calibration.bin_sums([], [])}
    right = judge.right(state, truth.edge[frame], truth.xy[frame])
    step = localized_step(right, driven, confirm_m)
    out = {"steps": float(len(frame)), "length_m": float(truth.driven[-1] - truth.driven[start]),
           "localized_m": float(driven[step]) if step is not None else np.nan,
           "accuracy_after": float(right[step:].mean()) if step is not None else np.nan,
           "position_error_m": np.nan,
           "confident_wrong": float(np.mean(~right & (np.asarray(confidence) >= sure)))}
    if xy is not None and step is not None:
        err = np.hypot(*(np.asarray(xy, float)[step:] - truth.xy[frame[step:]]).T)
        if np.isfinite(err).any():
            out["position_error_m"] = float(np.nanmedian(err))
    return out | calibration.bin_sums(confidence, right)


def summarize(starts: pd.DataFrame) -> pd.DataFrame:
    """Per drive and localizer (and ``all`` drives): median / p90 distance to localized, share localized,
    accuracy after (weighted by steps), median position error, confident-wrong share, the expected calibration
    error of all answers (``ece``, where the rows carry the bin sums of :func:`score_start`), and the same
    figures of the oracle, with the median ratio on the starts the oracle resolves."""
    rows = []
    for drive in [*starts.drive.unique(), "all"]:
        part = starts if drive == "all" else starts[starts.drive == drive]
        for name, group in part.groupby("localizer", sort=False):
            localized = group.localized_m.to_numpy(float)
            resolved = np.isfinite(group.oracle_m.to_numpy(float))
            ratio = group.ratio.to_numpy(float)[resolved]
            steps_after = group.steps.to_numpy(float) * np.isfinite(group.accuracy_after.to_numpy(float))
            acc = group.accuracy_after.fillna(0.0).to_numpy(float)
            rows.append({
                "drive": drive, "localizer": name, "starts": len(group),
                "localized_share": float(np.mean(np.isfinite(localized))),
                "median_m": quantile(localized, 50), "p90_m": quantile(localized, 90),
                "accuracy_after": float(np.average(acc, weights=steps_after)) if steps_after.sum() else np.nan,
                "position_error_m": float(np.nanmedian(group.position_error_m)) if group.position_error_m.notna().any() else np.nan,
                "confident_wrong": float(np.average(group.confident_wrong, weights=group.steps)) if group.steps.sum() else 0.0,
                "ece": calibration.ece(group) if calibration.COLUMNS[0] in group else np.nan,
                "oracle_resolved": float(np.mean(resolved)),
                "oracle_median_m": quantile(group.oracle_m.to_numpy(float), 50),
                "oracle_p90_m": quantile(group.oracle_m.to_numpy(float), 90),
                "localized_where_resolved": float(np.mean(np.isfinite(localized[resolved]))) if resolved.any() else np.nan,
                "median_ratio": float(np.nanmedian(ratio)) if np.isfinite(ratio).any() else np.nan,
            })
    return pd.DataFrame(rows)


def quantile(values: NDArray[np.float64], q: float) -> float:
    """The ``q``-th percentile over all starts, never-localized starts counting as infinitely far (NaN if
    that percentile is never reached)."""
    values = np.where(np.isfinite(values), values, np.inf)
    if len(values) == 0:
        return np.nan
    value = float(np.percentile(values, q, method="inverted_cdf"))
    return value if np.isfinite(value) else np.nan
