"""Stage ``localize_repeat``: the repeat drives localized on the teach map, per condition, network vs baseline.

Per repeat condition the drive's odometry is drawn from the noise model (an independent scale error per
drive, :mod:`topoloc.place.odometry`) and the loop of :mod:`topoloc.place.localize` runs with

* **siamese network**: the network's probability of "same place" on the backbone embeddings, threshold
  ``localize.threshold`` (paper: 0.8);
* **raw correlation** (baseline): normalised cross-correlation of grey images downsampled to
  ``localize.correlation_size``, threshold ``localize.correlation_threshold``;
* **odometry only** (reference): path integration alone, no retrieval;

and, beyond the paper, the network and the baseline again in the Bayes filter of
:mod:`topoloc.place.markov` (``+ filter``: the same scores over all vertices, settings
``localize.filter``).

A frame is localized within ``r`` metres when the ground-truth position of its estimated vertex is within
``r`` of the repeat frame's ground truth. Outputs: per-frame results (``frames``), a per-condition summary
(``summary``), the tables (``table``, like the paper's Tables 1 and 2: the mean and one column per
condition, held-out conditions marked), metrics and two figures.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
import pandas as pd
import torch
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.io import atomic_path, write_json, write_text
from topoloc.place.images import PlaceSet
from topoloc.place.localize import (MATCH, RELOC_FAIL, RELOC_OK, CorrelationScorer, LocalizeSettings, NetworkScorer,
                                    Trace, correlation_descriptors, localize, nearest_vertex)
from topoloc.place.markov import FilterSettings, markov_localize
from topoloc.place.network import load_model
from topoloc.place.odometry import noisy_odometry
from topoloc.place.plot import bars_figure, errors_figure
from topoloc.place.topometric_map import TopometricMap
from topoloc.render.conditions import check_conditions

log = logging.getLogger(__name__)

METHODS = ("siamese network", "siamese network + filter", "raw correlation", "raw correlation + filter", "odometry only")
SHORT_NAMES = dict(zip(METHODS, ("network", "network_filter", "correlation", "correlation_filter", "odometry")))


def settings_from(conf: dict[str, Any], threshold_key: str = "threshold") -> LocalizeSettings:
    """Loop settings from the ``place.localize`` slice, with the threshold of ``threshold_key``."""
    loc = conf["localize"]
    return LocalizeSettings(float(loc[threshold_key]), int(loc["window"]), int(loc["search_every"]),
                            int(loc["lost_frames"]), int(loc["reloc_images"]), int(loc["reloc_span"]),
                            int(loc["sequence_frames"]))


def filter_settings(conf: dict[str, Any]) -> FilterSettings:
    """Bayes filter settings from the ``place.localize.filter`` slice."""
    f = conf["localize"]["filter"]
    return FilterSettings(float(f["floor"]), float(f["mixing"]), float(f["motion_sigma_m"]), float(f["motion_sigma_rel"]))


def dead_reckoning(vertex_s: NDArray[np.float64], ds: NDArray[np.float64]) -> Trace:
    """Path integration alone from vertex 0: the reference without retrieval."""
    s = vertex_s[0] + np.cumsum(np.concatenate([[0.0], np.asarray(ds, float)[1:]]))
    vertex = np.array([nearest_vertex(vertex_s, v) for v in s], np.int64)
    return Trace(s, vertex, ["odometry"] * len(s), np.full(len(s), np.nan))


def frame_table(trace: Trace, topo: TopometricMap, gt_xy: NDArray[np.float64], condition: str, method: str) -> pd.DataFrame:
    """One row per repeat frame: estimate, error, event, score."""
    error = np.hypot(*(topo.gt_xy[trace.vertex] - gt_xy).T)
    return pd.DataFrame({"condition": condition, "method": method, "frame": np.arange(len(gt_xy)),
                         "gt_x": gt_xy[:, 0], "gt_y": gt_xy[:, 1], "vertex": trace.vertex, "s": trace.s,
                         "error_m": error, "event": trace.event, "score": trace.score})


def summarize(frames: pd.DataFrame) -> pd.DataFrame:
    """Per condition and method: shares within 5 / 2 m, errors, matches, false matches, relocalizations."""
    rows = []
    for (condition, method), g in frames.groupby(["condition", "method"], sort=False):
        matched = g[g.event == MATCH]
        rows.append({"condition": condition, "method": method, "frames": len(g),
                     "within_5m": float(np.mean(g.error_m <= 5.0)), "within_2m": float(np.mean(g.error_m <= 2.0)),
                     "mean_error_m": float(g.error_m.mean()), "median_error_m": float(g.error_m.median()),
                     "max_error_m": float(g.error_m.max()), "matches": len(matched),
                     "false_matches": int(np.sum(matched.error_m > 5.0)),
                     "relocalizations": int(np.sum(g.event == RELOC_OK)),
                     "failed_relocalizations": int(np.sum(g.event == RELOC_FAIL))})
    return pd.DataFrame(rows)


def paper_table(summary: pd.DataFrame, column: str, held_out: list[str], fmt: str = "{:.3f}") -> str:
    """A markdown table like the paper's Tables 1 and 2: one row per method, the mean, one column per condition."""
    conditions = list(dict.fromkeys(summary.condition))
    header = ["method", "Mean", *[f"{c} (held out)" if c in held_out else c for c in conditions]]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for method in dict.fromkeys(summary.method):
        rows = summary[summary.method == method].set_index("condition").loc[conditions, column]
        lines.append("| " + " | ".join([method, fmt.format(rows.mean()), *[fmt.format(v) for v in rows]]) + " |")
    return "\n".join(lines)


def tables_markdown(summary: pd.DataFrame, names: dict[str, list[str]], facts: dict[str, float]) -> str:
    """All tables of the stage, with a caption each."""
    held = names["held_out"]
    parts = [f"# Teach-and-repeat localization (teach: {names['teach'][0]}; held out of training: {', '.join(held)})", "",
             f"Repeat drives of {int(facts['repeat_frames'])} frames on a map of {int(facts['vertices'])} vertices.", ""]
    for title, column, fmt in (("Share of repeat frames localized within 5 m", "within_5m", "{:.3f}"),
                               ("Share of repeat frames localized within 2 m", "within_2m", "{:.3f}"),
                               ("Global relocalizations (successful)", "relocalizations", "{:.0f}"),
                               ("Accepted window matches", "matches", "{:.0f}"),
                               ("Accepted matches more than 5 m off", "false_matches", "{:.0f}"),
                               ("Median localization error (m)", "median_error_m", "{:.2f}")):
        parts += [f"## {title}", "", paper_table(summary, column, held, fmt), ""]
    parts.append(f"Network embedding: {facts['embed_images_per_s']:.0f} images/s on this machine.")
    return "\n".join(parts) + "\n"


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Localize every repeat condition of ``inputs['repeat']`` on ``inputs['map']`` with ``inputs['model']``."""
    torch.set_num_threads(int(conf["threads"]))
    names = check_conditions(conf)
    model = load_model(inputs["model"])
    topo = TopometricMap.load(inputs["map"])
    repeat = PlaceSet.load(inputs["repeat"])
    missing = [c for c in names["repeat"] if c not in repeat.conditions]
    if missing:
        raise InputError("place.repeat_conditions", f"{missing} not rendered in {inputs['repeat']}")
    vertex_s = topo.s
    net_settings, corr_settings = settings_from(conf), settings_from(conf, "correlation_threshold")
    filter_conf = filter_settings(conf)
    size = tuple(conf["localize"]["correlation_size"])
    if topo.descriptor.shape[1] != size[0] * size[1]:
        raise InputError("place.localize.correlation_size", f"{size} differs from the map's descriptors (rebuild the map)")
    tables, embed_s, embedded = [], 0.0, 0
    for k, condition in enumerate(names["repeat"]):
        images = repeat.condition(condition)
        odometry = noisy_odometry(repeat.xy, repeat.yaw, conf["odometry_noise"], np.random.default_rng([int(conf["seed"]), 29, k]))
        started = time.perf_counter()
        queries = model.embed(images)
        embed_s += time.perf_counter() - started
        embedded += len(images)
        descriptors = correlation_descriptors(images, size)
        traces = {
            "siamese network": localize(vertex_s, odometry.ds, NetworkScorer(model, queries, topo.embedding), net_settings),
            "siamese network + filter": markov_localize(vertex_s, odometry.ds, model.score_matrix(queries, topo.embedding),
                                                        filter_conf),
            "raw correlation": localize(vertex_s, odometry.ds, CorrelationScorer(descriptors, topo.descriptor), corr_settings),
            "raw correlation + filter": markov_localize(vertex_s, odometry.ds, descriptors @ topo.descriptor.T, filter_conf),
            "odometry only": dead_reckoning(vertex_s, odometry.ds),
        }
        for method, trace in traces.items():
            tables.append(frame_table(trace, topo, repeat.xy, condition, method))
        log.info("%s: %s", condition, {m: round(float(np.mean(t.error_m <= 5.0)), 3) for m, t in
                                       ((tab.method.iat[0], tab) for tab in tables[-len(traces):])})
    frames = pd.concat(tables, ignore_index=True)
    summary = summarize(frames)
    summary.insert(1, "held_out", summary.condition.isin(names["held_out"]))
    facts = {"repeat_frames": float(len(repeat)), "vertices": float(len(topo)),
             "embed_images_per_s": embedded / max(embed_s, 1e-9)}
    with atomic_path(outputs["frames"]) as tmp:
        frames.to_csv(tmp, index=False, float_format="%.3f")
    with atomic_path(outputs["summary"]) as tmp:
        summary.to_csv(tmp, index=False, float_format="%.4f")
    write_text(outputs["table"], tables_markdown(summary, names, facts))
    bars_figure(summary, outputs["bars"], names["held_out"])
    errors_figure(frames, outputs["errors"])
    metrics = dict(facts)
    for row in summary.itertuples():
        for key in ("within_5m", "within_2m", "relocalizations", "false_matches", "median_error_m"):
            metrics[f"{SHORT_NAMES[row.method]}_{key}_{row.condition}"] = float(getattr(row, key))
    for method, g in summary.groupby("method"):
        metrics[f"{SHORT_NAMES[method]}_within_5m_mean"] = float(g.within_5m.mean())
        metrics[f"{SHORT_NAMES[method]}_within_5m_min"] = float(g.within_5m.min())
        metrics[f"{SHORT_NAMES[method]}_within_2m_mean"] = float(g.within_2m.mean())
    write_json(outputs["metrics"], metrics)
    return metrics
