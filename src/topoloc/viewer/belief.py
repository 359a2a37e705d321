"""The metric filter's belief along a drive, decimated for the viewer: at one moment every ``every_m`` metres
driven, the leading roads with their probabilities and a heat layer of the cells, summed on a grid coarse enough
to keep at most ``heat_points`` points (on a city map the early belief covers the whole city on a coarse grid, and
shrinks to one road on the finest)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from tqdm import tqdm

from topoloc.localization.roadmap import RoadMap
from topoloc.localizers.metric import MetricLocalizer
from topoloc.motion.poses import Odometry
from topoloc.viewer.page import LatLon


def heat_points(xy: NDArray[np.float64], weight: NDArray[np.float64], cell_m: float, most: int,
                latlon: LatLon) -> list[list[float]]:
    """``[[lat, lon, w], ...]``: the probability of the cells ``xy`` summed on a square grid of ``cell_m``, doubled
    until at most ``most`` grid cells hold probability; ``w`` relative to the largest, 3 decimals, tiny ones dropped."""
    keep = weight > 0
    xy, weight = np.asarray(xy, float)[keep], np.asarray(weight, float)[keep]
    if not len(weight):
        return []
    size = max(float(cell_m), 1e-3)
    while True:
        keys, inverse = np.unique(np.floor(xy / size).astype(np.int64), axis=0, return_inverse=True)
        if len(keys) <= most:
            break
        size *= 2.0
    inverse = inverse.reshape(-1)
    mass = np.bincount(inverse, weights=weight, minlength=len(keys))
    centre = np.column_stack([np.bincount(inverse, weights=weight * xy[:, k], minlength=len(keys)) for k in (0, 1)])
    centre /= np.maximum(mass, 1e-300)[:, None]
    w = np.round(mass / mass.max(), 3)
    shown = w >= 0.001
    return [[*ll, float(v)] for ll, v in zip(latlon(centre[shown]), w[shown])]


def belief_moments(road: RoadMap, odometry: Odometry, conf: dict[str, Any], every_m: float, top_roads: int,
                   most_points: int, latlon: LatLon) -> dict[str, Any]:
    """The metric filter from the drive's first frame, step by step; at the first step and then every
    ``every_m`` metres driven (and the last step): ``frame`` (the step's frame), ``roads`` (``[[edge, p], ...]``,
    the ``top_roads`` most probable roads) and ``heat`` (:func:`heat_points`); and ``answers``, the filter's answer
    at every step (an answers table: ``localizer`` metric, ``frame``, ``state``, ``confidence``, ``x``, ``y``)."""
    localizer = MetricLocalizer()
    observations = localizer.observe(odometry, road, conf)
    localizer.reset(road, conf)
    driven = odometry.driven_m
    cell_m = float(conf["localization"]["metric"]["cell_m"])
    out: dict[str, Any] = {"frame": [], "roads": [], "heat": []}
    steps: list[tuple[int, int, float, float, float]] = []
    next_m = -np.inf
    last = len(observations.items) - 1
    for j, item in enumerate(tqdm(observations.items, desc="belief", unit="step", mininterval=5, disable=None)):
        answer = localizer.update(item)
        frame = int(observations.frame[j])
        x, y = answer.xy if answer.xy is not None else (np.nan, np.nan)
        steps.append((frame, int(answer.state), float(answer.confidence), float(x), float(y)))
        if driven[frame] < next_m and j != last:
            continue
        next_m = driven[frame] + every_m
        filt = localizer.filter
        marginal = filt.road_marginals(0)
        total = float(marginal.sum())
        order = np.argsort(-marginal)[:top_roads]
        order = order[marginal[order] > 0]
        cell_xy, weight, _ = filt.belief(0)
        out["frame"].append(frame)
        out["roads"].append([[int(e), round(float(marginal[e]) / max(total, 1e-300), 4)] for e in order])
        out["heat"].append(heat_points(cell_xy, weight, cell_m, most_points, latlon))
    out["answers"] = pd.DataFrame(steps, columns=["frame", "state", "confidence", "x", "y"]).assign(localizer="metric")
    return out
