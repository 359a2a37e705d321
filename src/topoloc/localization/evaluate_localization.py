"""Stage ``evaluate_localization``: every localizer from many starts beside the oracle; tables and figures.

Inputs: ``graph``, and per drive ``<drive>`` of ``conf['drives']``: ``answers_<drive>`` and ``stats_<drive>``
(of ``decode_trajectories``), ``frames_<drive>`` (truth) and ``segments_<drive>`` (for Fig. 9 (a)).
Per start (:mod:`topoloc.localization.evaluation`): distance to localized, accuracy after, position
error, confident wrong answers, and the oracle's uniqueness limit (:mod:`topoloc.localization.oracle`)
with the ratio to it. Outputs: ``starts`` (CSV, one row per drive, start and localizer), ``csv``
(summary per drive and localizer, and over all drives), ``table`` (markdown: the summary beside the
oracle, then the frame-0 figures), ``metrics`` (JSON), ``cdf`` (distance to localized over all starts,
every localizer and the oracle), ``reliability`` (the reliability diagram of every localizer's answers over all
starts and drives, :mod:`topoloc.localization.calibration`) and ``fig9_<drive>`` (the paper's Fig. 9 panels,
frame 0). Metrics: per localizer its figures over all drives, among them ``<localizer>_ece``.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json, write_text
from topoloc.localization import calibration
from topoloc.localization.connectivity import connected_keys, consecutive_connected, directed_edges
from topoloc.localization.evaluation import DriveTruth, Judge, score_start, summarize
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.plot import plot_cdf, plot_fig9, plot_reliability
from topoloc.registry import registry

log = logging.getLogger(__name__)

ORACLE = "oracle"


def label(name: str) -> str:
    """Table label of a localizer (the registry's), or the name itself."""
    known = registry()
    return known[name].label if name in known else ("oracle (uniqueness limit of the map)" if name == ORACLE else name)


def score_drive(drive: str, graph: RoadGraph, answers: pd.DataFrame, frames: pd.DataFrame, oracle: Oracle, judge: Judge,
                conf: dict[str, Any]) -> pd.DataFrame:
    """One row per start and localizer (and the oracle) of one drive."""
    ev = conf["evaluate"]
    confirm, sure = float(ev["confirm_m"]), float(ev["sure"])
    truth = DriveTruth.from_frames(frames)
    path = true_path(graph, truth.edge, truth.xy, truth.driven)
    rows = []
    for start in sorted(answers.start.unique()):
        limit = oracle.count(path, int(start), confirm)
        rows.append({"drive": drive, "start": int(start), "start_m": float(truth.driven[start]), "localizer": ORACLE,
                     "steps": float(len(frames) - start), "length_m": float(truth.driven[-1] - truth.driven[start]),
                     "localized_m": limit.localized_m, "oracle_m": limit.localized_m, "ratio": 1.0 if np.isfinite(limit.localized_m) else np.nan})
        for name, run in answers[answers.start == start].groupby("localizer", sort=False):
            m = score_start(judge, truth, int(start), run.frame.to_numpy(), run.state.to_numpy(), run.confidence.to_numpy(),
                            run[["x", "y"]].to_numpy(float), confirm, sure)
            ratio = np.nan
            if np.isfinite(limit.localized_m):
                ratio = m["localized_m"] / limit.localized_m if np.isfinite(m["localized_m"]) else np.inf
            rows.append({"drive": drive, "start": int(start), "start_m": float(truth.driven[start]), "localizer": name, **m,
                         "oracle_m": limit.localized_m, "ratio": ratio})
    return pd.DataFrame(rows)


def frame0(drive: str, answers: pd.DataFrame, starts: pd.DataFrame, frames: pd.DataFrame, judge: Judge, states, keys) -> pd.DataFrame:
    """The frame-0 figures of every localizer of one drive: step accuracy (online and traced-back path),
    consistency of the path, distance to localized and the oracle's, accuracy after, position error."""
    truth = DriveTruth.from_frames(frames)
    first = int(answers.start.min())
    rows = []
    for name, run in answers[answers.start == first].groupby("localizer", sort=False):
        frame = run.frame.to_numpy()
        right = judge.right(run.state.to_numpy(), truth.edge[frame], truth.xy[frame])
        right_path = judge.right(run.path.to_numpy(), truth.edge[frame], truth.xy[frame])
        connected = consecutive_connected(states, run.path.to_numpy()[run.path.to_numpy() >= 0], keys)
        scored = starts[(starts.start == first) & (starts.localizer == name)].iloc[0]
        rows.append({"drive": drive, "localizer": name, "steps": len(run), "km": float(truth.driven[frame[-1]] - truth.driven[first]) / 1000,
                     "accuracy": float(right.mean()), "path_accuracy": float(right_path.mean()),
                     "consistency": float(connected.mean()) if len(connected) else 1.0,
                     "localized_m": scored.localized_m, "oracle_m": scored.oracle_m, "accuracy_after": scored.accuracy_after,
                     "position_error_m": scored.position_error_m, "confident_wrong": scored.confident_wrong})
    return pd.DataFrame(rows)


def _fmt(value: float, kind: str = "f") -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "never" if kind == "m" else "-"
    return {"m": f"{value:.0f}", "f": f"{value:.3f}", "i": f"{int(value)}", "x": f"{value:.2f}", "p": f"{100 * value:.1f} %"}[kind]


def reliability_lines(starts: pd.DataFrame) -> list[str]:
    """The calibration section: per localizer its ECE over all answers and its reliability diagram as a table
    (share right / answers per confidence bin)."""
    rows = {name: group for name, group in starts.groupby("localizer", sort=False) if name != ORACLE}
    bins = calibration.reliability(next(iter(rows.values()))) if rows else pd.DataFrame()
    head = ["localizer", "ECE", *(f"{lo:.1f}-{hi:.1f}" for lo, hi in zip(bins.get("low", []), bins.get("high", [])))]
    lines = ["## Calibration", "",
             "Over every answer of every start and drive: the share right (the judge above) of the answers per "
             "confidence bin, and their number; ECE = the expected calibration error (the answers' mean gap between "
             "confidence and share right in their bin; 0 is perfectly calibrated).", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, group in rows.items():
        table = calibration.reliability(group)
        cells = [("-" if n == 0 else f"{share:.2f} ({n})") for share, n in zip(table.share_right, table.answers)]
        lines.append("| " + " | ".join([label(name), _fmt(calibration.ece(group)), *cells]) + " |")
    return lines


def markdown(summary: pd.DataFrame, first: pd.DataFrame, region: str, ev: dict[str, Any], starts: pd.DataFrame | None = None) -> str:
    """The localization tables of a config (with ``starts``, the per-start rows, also the calibration section)."""
    head = ["drive", "localizer", "starts", "localized", "median (m)", "p90 (m)", "median ratio to oracle",
            "acc. after", "position error (m)", "confident wrong", "ECE"]
    lines = [f"# Localization on {region}", "",
             f"From a start every {ev['start_every_m']:.0f} m of each drive (nothing before it known). Localized = the "
             f"start of the first stretch of >= {ev['confirm_m']:.0f} m of right answers (the true road, or one meeting it "
             f"at a node within {ev['node_tolerance_m']:.0f} m). Median and p90 over all starts (never localized counts as "
             f"infinitely far); ratio = localized / oracle on the starts the oracle resolves; confident wrong = wrong "
             f"answers with confidence >= {ev['sure']}. The oracle: the distance after which exactly one walk on the map "
             f"agrees with the drive's turns (within {ev['oracle']['angle_tol_deg']:.0f} deg) and road lengths (within "
             f"{100 * ev['oracle']['length_tol']:.0f} %).", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, r in summary.iterrows():
        is_oracle = r.localizer == ORACLE
        lines.append("| " + " | ".join([
            f"**{r.drive}**" if r.drive == "all" else str(r.drive), label(r.localizer), _fmt(r.starts, "i"),
            _fmt(r.localized_share, "p"), _fmt(r.median_m, "m"), _fmt(r.p90_m, "m"),
            "1" if is_oracle else _fmt(r.median_ratio, "x"), "" if is_oracle else _fmt(r.accuracy_after),
            "" if is_oracle else _fmt(r.position_error_m, "x"), "" if is_oracle else _fmt(r.confident_wrong, "p"),
            "" if is_oracle else _fmt(r.get("ece", np.nan))]) + " |")
    head0 = ["drive", "localizer", "updates", "km", "step acc. (online)", "step acc. (path)", "consistency",
             "localized after (m)", "oracle (m)", "acc. after", "position error (m)"]
    lines += ["", "## From frame 0", "",
              "Online = the answer after each update; path = the consistent sequence traced back after the last one.", "",
              "| " + " | ".join(head0) + " |", "|" + "---|" * len(head0)]
    for _, r in first.iterrows():
        lines.append("| " + " | ".join([str(r.drive), label(r.localizer), _fmt(r.steps, "i"), f"{r.km:.2f}", _fmt(r.accuracy),
                                        _fmt(r.path_accuracy), _fmt(r.consistency), _fmt(r.localized_m, "m"),
                                        _fmt(r.oracle_m, "m"), _fmt(r.accuracy_after), _fmt(r.position_error_m, "x")]) + " |")
    if starts is not None:
        lines += ["", *reliability_lines(starts)]
    return "\n".join(lines) + "\n"


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Evaluate the drives ``conf['drives']``; write the tables, the CDF and Fig. 9 per drive."""
    loc = conf["localization"]
    ev = loc["evaluate"]
    graph = RoadGraph.load(inputs["graph"])
    states = directed_edges(graph, loc["decode"]["u_turns"], loc["decode"]["max_skip_m"])
    keys = connected_keys(states)
    oracle = Oracle(graph, states, float(ev["oracle"]["angle_tol_deg"]), float(ev["oracle"]["length_tol"]))
    judge = Judge(graph, float(ev["node_tolerance_m"]))
    per_start, first = [], []
    for drive in conf["drives"]:
        answers = pd.read_csv(inputs[f"answers_{drive}"])
        frames = pd.read_csv(inputs[f"frames_{drive}"])
        stats = json.loads(Path(inputs[f"stats_{drive}"]).read_text())
        starts = score_drive(drive, graph, answers, frames, oracle, judge, loc)
        per_start.append(starts)
        first.append(frame0(drive, answers, starts, frames, judge, states, keys))
        segments = pd.read_csv(inputs[f"segments_{drive}"])
        corners = np.append(segments.start_frame.to_numpy(), segments.end_frame.to_numpy()[-1:]) if len(segments) else None
        facts = stats["localizers"]
        initial = next((f["initial_hypotheses"] for f in facts.values() if f.get("initial_hypotheses")), [])  # config order
        plot_fig9(graph, answers[answers.start == answers.start.min()], frames, corners, initial[:int(ev["initial_hypotheses"])],
                  first[-1].set_index("localizer").to_dict(orient="index"), {n: label(n) for n in facts},
                  outputs[f"fig9_{drive}"], f"Fig. 9, {conf.get('region', '')} drive {drive}, from frame 0")
    starts = pd.concat(per_start, ignore_index=True)
    summary = summarize(starts)
    first_table = pd.concat(first, ignore_index=True)
    with atomic_path(outputs["starts"]) as tmp:
        starts.to_csv(tmp, index=False, float_format="%.4f")
    with atomic_path(outputs["csv"]) as tmp:
        summary.to_csv(tmp, index=False, float_format="%.4f")
    write_text(outputs["table"], markdown(summary, first_table, conf.get("region", ""), ev, starts))
    diagrams = {label(n): d for n, d in calibration.reliability_per(starts, skip=[ORACLE]).items()}
    plot_reliability(diagrams, outputs["reliability"],
                     f"{conf.get('region', '')}: reliability of the answers' confidence, all starts and drives")
    plot_cdf(starts, {n: label(n) for n in starts.localizer.unique()}, outputs["cdf"],
             f"{conf.get('region', '')}: distance driven until localized, {len(starts[starts.localizer == ORACLE])} starts")
    write_json(outputs["metrics"], {"summary": summary.to_dict(orient="records"), "frame0": first_table.to_dict(orient="records")})
    metrics: dict[str, float] = {}
    for _, r in summary[summary.drive == "all"].iterrows():
        for col in ("localized_share", "median_m", "p90_m", "median_ratio", "accuracy_after", "position_error_m", "confident_wrong", "ece"):
            if np.isfinite(r[col]):
                metrics[f"{r.localizer}_{col}"] = float(r[col])
    log.info("localization: %s", metrics)
    return metrics
