"""Stage ``evaluate_localization``: per drive and aggregated metrics of every decoder, a markdown table, Fig. 9 per drive.

Inputs: ``graph``, and per drive ``<drive>`` of ``conf['drives']``:
``decoded_<drive>`` (table of ``decode_trajectories``), ``stats_<drive>`` (its
JSON), ``frames_<drive>`` and ``segments_<drive>`` (odometry and its
segments, for panel (a)). Outputs: ``table`` (markdown), ``csv`` (one row per
drive and decoder, plus ``all``), ``metrics`` (JSON) and ``fig9_<drive>``.
Metrics: :mod:`topoloc.localization.metrics`.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json, write_text
from topoloc.localization.connectivity import connected_keys, directed_edges
from topoloc.localization.localize import DECODERS, LABELS
from topoloc.localization.metrics import drive_metrics
from topoloc.localization.plot import plot_fig9

log = logging.getLogger(__name__)

COLUMNS = ["accuracy", "path_accuracy", "consistency", "localized_m", "accuracy_after", "path_accuracy_after", "right_from_m"]


def evaluate_drive(table: pd.DataFrame, states, confirm_m: float, keys=None) -> dict[str, dict[str, float]]:
    """Metrics of every decoder in a decoded table (needs ``true_edge_id``)."""
    if "true_edge_id" not in table.columns:
        raise InputError("decoded table", "has no ground-truth edges (true_edge_id); nothing to evaluate")
    distance = table["distance_m"].to_numpy(float) if "distance_m" in table.columns else np.arange(len(table), dtype=float)
    out = {}
    for name in DECODERS:
        if f"{name}_online" in table.columns:
            out[name] = drive_metrics(table.true_edge_id.to_numpy(), table[f"{name}_online"].to_numpy(),
                                      table[f"{name}_path"].to_numpy(), distance, states, confirm_m, keys)
    return out


def aggregate(rows: pd.DataFrame) -> pd.DataFrame:
    """Per decoder over drives: step-weighted accuracies, mean consistency, mean localization distance, share localized."""
    out = []
    for name, group in rows.groupby("decoder", sort=False):
        w = group.steps.to_numpy(float)
        after_steps = group.steps_after.to_numpy(float)  # steps from localization on, per drive
        row = {"drive": "all", "decoder": name, "steps": w.sum(), "length_m": group.length_m.sum(),
               "accuracy": np.average(group.accuracy, weights=w), "path_accuracy": np.average(group.path_accuracy, weights=w),
               "consistency": np.average(group.consistency, weights=w), "localized_m": group.localized_m.mean(),
               "accuracy_after": np.average(group.accuracy_after.fillna(0), weights=after_steps) if after_steps.sum() else np.nan,
               "path_accuracy_after": np.average(group.path_accuracy_after.fillna(0), weights=after_steps) if after_steps.sum() else np.nan,
               "right_from_m": group.right_from_m.mean(), "restarts": group.restarts.sum(),
               "localized_share": float(group.localized_m.notna().mean())}
        out.append(row)
    return pd.DataFrame(out)


def _fmt(value: float, kind: str) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "never" if kind == "m" else "-"
    return f"{value:.0f}" if kind == "m" else f"{value:.3f}" if kind == "f" else str(int(value))


def markdown(frame: pd.DataFrame, region: str, confirm_m: float, k: int) -> str:
    """The localization table of a config."""
    head = ["drive", "decoder", "steps", "km", "step acc. (online)", "step acc. (decoded seq.)", "consistency",
            "localized after (m)", "online acc. after", "right from (m)", "breaks"]
    lines = [f"# Localization on {region}", "",
             f"Online = the best hypothesis after each step; decoded sequence = the best final hypothesis traced back. "
             f"Localized = start of the first stretch of >= {confirm_m:.0f} m with the right online edge; k = {k}.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, r in frame.iterrows():
        lines.append("| " + " | ".join([
            f"**{r.drive}**" if r.drive == "all" else str(r.drive), LABELS.get(r.decoder, r.decoder), _fmt(r.steps, "i"),
            f"{r.length_m / 1000:.2f}", _fmt(r.accuracy, "f"), _fmt(r.path_accuracy, "f"), _fmt(r.consistency, "f"),
            _fmt(r.localized_m, "m"), _fmt(r.accuracy_after, "f"), _fmt(r.right_from_m, "m"), _fmt(r.restarts, "i"),
        ]) + " |")
    return "\n".join(lines) + "\n"


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Evaluate the decoded drives ``conf['drives']``; write ``table``, ``csv``, ``metrics`` and ``fig9_<drive>``."""
    graph = RoadGraph.load(inputs["graph"])
    dec_conf, ev_conf = conf["localization"]["decode"], conf["localization"]["evaluate"]
    states = directed_edges(graph, dec_conf["u_turns"], dec_conf.get("max_skip_m"))
    keys = connected_keys(states)
    confirm_m = float(ev_conf["confirm_m"])
    rows = []
    for drive in conf["drives"]:
        table = pd.read_csv(inputs[f"decoded_{drive}"])
        stats = json.loads(Path(inputs[f"stats_{drive}"]).read_text())
        per = evaluate_drive(table, states, confirm_m, keys)
        for name, m in per.items():
            rows.append({"drive": drive, "decoder": name, **m, "restarts": stats["decoders"].get(name, {}).get("restarts", 0)})
        frames = pd.read_csv(inputs[f"frames_{drive}"])
        segments = pd.read_csv(inputs[f"segments_{drive}"])
        corners = np.append(segments.start_frame.to_numpy(), segments.end_frame.to_numpy()[-1:]) if len(segments) else None
        initial = stats["decoders"].get("strategy1", stats["decoders"].get("raw", {})).get("initial_hypotheses", [])
        title = (f"Fig. 9, {conf.get('region', '')} drive {drive}: {len(table)} tokens, "
                 f"{per['raw']['length_m'] / 1000:.2f} km")
        plot_fig9(graph, table, frames, corners, initial[:int(ev_conf["initial_hypotheses"])], per, outputs[f"fig9_{drive}"], title)
    frame = pd.DataFrame(rows)
    total = aggregate(frame)
    full = pd.concat([frame, total], ignore_index=True)
    with atomic_path(outputs["csv"]) as tmp:
        full.to_csv(tmp, index=False, float_format="%.4f")
    write_text(outputs["table"], markdown(full, conf.get("region", ""), confirm_m, int(dec_conf["k"])))
    metrics: dict[str, float] = {}
    for _, r in total.iterrows():
        for col in (*COLUMNS, "localized_share"):
            if np.isfinite(r[col]):
                metrics[f"{r.decoder}_{col}"] = float(r[col])
    write_json(outputs["metrics"], {"drives": rows, "all": total.to_dict(orient="records")})
    log.info("localization: %s", metrics)
    return metrics
