"""Stage ``localize_repeat``: the repeat drives localized on the teach map, per condition, network vs baseline.

Per repeat condition the drive's odometry is drawn from the noise model (an independent scale error per
drive, :mod:`topoloc.place.odometry`) and the place localizers of ``localize.localizers`` (registry names,
:mod:`topoloc.localizers`: ``place_loop``, the paper's loop of :mod:`topoloc.place.topometric_localization`;
``place_filter``, beyond the paper, the Bayes filter of :mod:`topoloc.place.markov`, settings
``localize.filter``; ``place_odometry``, path integration alone, the reference) run on the frames scored by

* **siamese network**: the network's probability of "same place" on the backbone embeddings, threshold
  ``localize.threshold`` (paper: 0.8);
* **raw correlation** (baseline): normalised cross-correlation of grey images downsampled to
  ``localize.correlation_size``, threshold ``localize.correlation_threshold``.

A localizer's table row is its ``row`` with the scorer's name (``siamese network``, ``siamese network +
filter``, ...); one that looks at no image (``odometry only``) runs once per condition.

A frame is localized within ``r`` metres when the ground-truth position of its estimated vertex is within
``r`` of the repeat frame's ground truth. Outputs: per-frame results (``frames``), a per-condition summary
(``summary``), the tables (``table``, like the paper's Tables 1 and 2: the mean and one column per
condition, held-out conditions marked), metrics and two figures.
"""

from __future__ import annotations

import logging
import time
from typing import Any, cast

import numpy as np
import pandas as pd
import torch
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.io import atomic_path, write_json, write_text
from topoloc.localizer import PLACE_OBSERVATIONS, run_batch
from topoloc.place.images import PlaceSet
from topoloc.place.network import load_model
from topoloc.place.odometry import noisy_odometry
from topoloc.place.plot import bars_figure, errors_figure
from topoloc.place.topometric_localization import (
    MATCH,
    RELOC_FAIL,
    RELOC_OK,
    CorrelationScorer,
    NetworkScorer,
    PlaceLocalizer,
    Scorer,
    Trace,
    correlation_descriptors,
    drive_frames,
)
from topoloc.place.topometric_map import TopometricMap
from topoloc.registry import check_names, make
from topoloc.render.conditions import check_conditions
from topoloc.report_tables import condition_table

log = logging.getLogger(__name__)

#: The scorers: table name, metric name, the ``place.localize`` key of the loop's threshold on their scale.
SCORERS = (("siamese network", "network", "threshold"), ("raw correlation", "correlation", "correlation_threshold"))


def methods(localizers: list[PlaceLocalizer]) -> list[tuple[str, str, PlaceLocalizer, int | None]]:
    """(table row, metric name, localizer, scorer index or None) of every run per condition, in table order:
    every localizer that scores images with each scorer in turn, then those that look at no image."""
    runs = [(loc.row.format(scores=name), loc.metric.format(scores=short), loc, k)
            for k, (name, short, _) in enumerate(SCORERS) for loc in localizers if "{scores}" in loc.row]
    return runs + [(loc.row, loc.metric, loc, None) for loc in localizers if "{scores}" not in loc.row]


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
        parts += [f"## {title}", "", condition_table(summary, "method", column, held, fmt, "method"), ""]
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
    loc = conf["localize"]
    localizers = check_names(loc["localizers"], "place.localize.localizers", PLACE_OBSERVATIONS)
    runs = methods([cast(PlaceLocalizer, make(name, PLACE_OBSERVATIONS)) for name in localizers])
    short_names = {method: short for method, short, _, _ in runs}
    size = tuple(loc["correlation_size"])
    if topo.descriptor.shape[1] != size[0] * size[1]:
        raise InputError("place.localize.correlation_size", f"{size} differs from the map's descriptors (rebuild the map)")
    tables, embed_s, embedded = [], 0.0, 0
    for k, condition in enumerate(names["repeat"]):
        images = repeat.condition(condition)
        odometry, _ = noisy_odometry(repeat.xy, repeat.yaw, conf["odometry_noise"], np.random.default_rng([int(conf["seed"]), 29, k]))
        started = time.perf_counter()
        queries = model.embed(images)
        embed_s += time.perf_counter() - started
        embedded += len(images)
        scorers: list[Scorer] = [NetworkScorer(model, queries, topo.embedding),
                                 CorrelationScorer(correlation_descriptors(images, size), topo.descriptor)]
        observed = [drive_frames(odometry.ds, scorer) for scorer in scorers]
        for method, _, localizer, scorer in runs:
            scorer = 0 if scorer is None else scorer  # a localizer that looks at no image reads only the odometry
            # the loop's threshold is on the scale of the scores: the network's threshold, or the baseline's
            track = run_batch(localizer, topo, {**loc, "threshold": loc[SCORERS[scorer][2]]}, observed[scorer])
            tables.append(frame_table(track.extra["trace"], topo, repeat.xy, condition, method))
        log.info("%s: %s", condition, {m: round(float(np.mean(t.error_m <= 5.0)), 3) for m, t in
                                       ((tab.method.iat[0], tab) for tab in tables[-len(runs):])})
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
            metrics[f"{short_names[row.method]}_{key}_{row.condition}"] = float(getattr(row, key))
    for method, g in summary.groupby("method"):
        metrics[f"{short_names[method]}_within_5m_mean"] = float(g.within_5m.mean())
        metrics[f"{short_names[method]}_within_5m_min"] = float(g.within_5m.min())
        metrics[f"{short_names[method]}_within_2m_mean"] = float(g.within_2m.mean())
    write_json(outputs["metrics"], metrics)
    return metrics
