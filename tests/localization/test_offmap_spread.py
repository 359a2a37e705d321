"""``localization.metric.offmap_spread``: how sharply the off-map state predicts the heading (a factor on the noise of
two observations). A road whose polyline jogs sideways (two opposite kinks 30 m apart, as OSM draws a road that
shifts) is driven as one smooth S; over 43 m (21 steps) the map's heading is 10-33 deg off the drive's, and the off-map
state, which only asks each heading to follow the last, explains them better. A wider off-map spread keeps the belief
on the road (measured on the benchmarks in docs/localization.md, where it is not kept: it also keeps the belief on the
map after a stretch the map lacks)."""

from __future__ import annotations

import numpy as np
from localization_helpers import make_graph
from scipy.ndimage import gaussian_filter1d

from topoloc.config import load
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.registry import make


def _jogging_road(angle_deg: float = 66.0, jog_m: float = 30.0):
    """Road 0 runs east 200 m, jogs ``jog_m`` at ``angle_deg`` to the north, runs east 200 m again; short side roads
    at both ends (not dead ends). Returns the graph and road 0's polyline."""
    a = np.radians(angle_deg)
    kink_a, kink_b = (200.0, 0.0), (200.0 + jog_m * np.cos(a), jog_m * np.sin(a))
    end = (kink_b[0] + 200.0, kink_b[1])
    coords = {0: (0.0, 0.0), 1: end, 2: (0.0, -60.0), 3: (end[0], end[1] + 70.0)}
    return make_graph(coords, [(0, 1, 0, [kink_a, kink_b]), (0, 2), (1, 3)]), [coords[0], kink_a, kink_b, end]


def _smoothed_drive(points, smoothing_m: float, every_m: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Positions and headings along the polyline ``points`` smoothed by a Gaussian of ``smoothing_m`` (as the
    map-error benchmark's ``wide_turns`` drives round corners)."""
    pts = np.asarray(points, float)
    pieces = [np.linspace(p, q, max(2, int(np.hypot(*(q - p)) / every_m)), endpoint=False) for p, q in zip(pts[:-1], pts[1:])]
    xy = gaussian_filter1d(np.vstack(pieces + [pts[-1:]]), smoothing_m / every_m, axis=0, mode="nearest")
    step = np.gradient(xy, axis=0)
    return xy, np.unwrap(np.arctan2(step[:, 1], step[:, 0]))


def _most_off_the_map(road: RoadMap, xy: np.ndarray, yaw: np.ndarray, **metric) -> tuple[float, int, float]:
    """The metric filter along the drive: the largest off-map probability, the last answer's road and confidence."""
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    conf["localization"]["metric"].update(metric)
    localizer = make("metric")
    observations = localizer.observe(Odometry(xy, yaw), road, conf)
    localizer.reset(road, conf)
    localizer.start()
    most = 0.0
    for item in observations.items:
        answer = localizer.update(item)
        most = max(most, localizer.filter.answer().offmap)
    return most, answer.state, answer.confidence


def test_a_wider_off_map_spread_keeps_a_widely_rounded_jog_on_the_map():
    graph, polyline = _jogging_road()
    road = RoadMap(graph)
    xy, yaw = _smoothed_drive(polyline, 10.0)
    off, state, confidence = _most_off_the_map(road, xy, yaw)
    assert off >= 0.9, off  # the defaults: the jog sends the belief off the map (1.00 when written)
    assert state == 0 and confidence >= 0.9  # and it comes back after it
    off, state, confidence = _most_off_the_map(road, xy, yaw, offmap_spread=3.0)
    assert off <= 0.05 and state == 0 and confidence >= 0.9, (off, state, confidence)  # 0.01: the prior
    # driven as drawn (rounded over 2 m), the jog is on the map with the defaults too
    off, _, _ = _most_off_the_map(road, *_smoothed_drive(polyline, 2.0))
    assert off <= 0.05, off
