"""Simulated drives on the road graph: ground truth and noisy odometry, as one :class:`SimulatedDrive` type.

Odometry integrates the true per-frame increments (distance ``ds``, heading change ``dpsi``) through the
noise model of :mod:`topoloc.motion.noise` (``scale_error``, ``distance_noise``,
``heading_drift_deg_per_100m``, ``heading_noise_deg``) from the true start pose; a drive's odometry is in
its own frame (``xy[0] = 0``, axes of the map; headings from the true first heading). Two makers:

* :func:`simulate_drive` (the ``extract_odometry`` stage's ``simulated`` source, fixed noise
  ``odometry.simulated.noise``): a random route (a walk over the graph that respects one-way roads and
  avoids U-turns unless at a dead end) of at least ``length_m``, sampled every ``frame_spacing_m`` along the
  road geometry (:mod:`topoloc.motion.route`); the heading is the direction of travel.
* :func:`simulate_pattern_drive` (drives for validating localizers): driven the way a car does
  (:func:`topoloc.motion.route.smooth_path`: in the right-hand lane, corners rounded), sampled about every
  metre, with the noise parameters drawn per drive from the ranges of a :class:`NoiseLevel` (the scale
  error and the drift with a random sign). Patterns: ``random`` (a random walk of the given length),
  ``circuit`` (a closed loop of roads driven twice), ``stop_reverse`` (a random walk with a long stop and a
  stretch driven backwards in the middle). The yaw of the odometry is the vehicle's heading, so a
  reversing stretch moves against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.noise import NOISE_KEYS, OdometryNoise, integrate_odometry
from topoloc.motion.poses import Odometry
from topoloc.motion.route import DENSE_M, random_route, sample_route, smooth_path


@dataclass(frozen=True)
class SimulatedDrive:
    """Ground truth per frame (map position ``gt_xy`` (n, 2), heading ``gt_yaw`` in rad from east, road
    ``edge``), the drive's odometry (its own frame), the noise parameters it was made with, its pattern
    (``route`` for :func:`simulate_drive`, else one of :data:`PATTERNS`) and the roads driven."""

    gt_xy: NDArray[np.float64]
    gt_yaw: NDArray[np.float64]
    edge: NDArray[np.int64]
    odometry: Odometry
    noise: dict[str, float]
    pattern: str
    route: list[int]

    @property
    def length_m(self) -> float:
        return float(np.hypot(*np.diff(self.gt_xy, axis=0).T).sum())


def simulate_drive(graph: RoadGraph, length_m: float, spacing_m: float, noise: dict[str, float], rng: np.random.Generator) -> SimulatedDrive:
    """One random drive with ground truth and odometry under the noise parameters ``noise`` (module docstring)."""
    route, froms = random_route(graph, length_m, rng)
    xy, labels = sample_route(graph, route, froms, spacing_m)
    step = np.diff(xy, axis=0)
    yaw_steps = np.arctan2(step[:, 1], step[:, 0])
    yaw = np.concatenate([yaw_steps[:1], yaw_steps])
    yaw = np.unwrap(yaw)
    odometry = integrate_odometry(xy, yaw, OdometryNoise.from_dict(noise), rng)
    return SimulatedDrive(xy, yaw, labels, odometry, dict(noise), "route", route)


PATTERNS = ("random", "circuit", "stop_reverse")


@dataclass(frozen=True)
class NoiseLevel:
    """Ranges ``(low, high)`` of the magnitudes of the noise parameters, drawn uniformly per drive."""

    name: str
    scale_error: tuple[float, float]
    distance_noise: tuple[float, float]
    heading_drift_deg_per_100m: tuple[float, float]
    heading_noise_deg: tuple[float, float]

    def draw(self, rng: np.random.Generator) -> dict[str, float]:
        """One drive's noise parameters (the scale error and the drift get a random sign)."""
        out = {}
        for key in NOISE_KEYS:
            low, high = getattr(self, key)
            value = float(rng.uniform(low, high))
            out[key] = value * (rng.choice([-1.0, 1.0]) if key in ("scale_error", "heading_drift_deg_per_100m") else 1.0)
        return out


#: KITTI 00's ORB-SLAM2 poses show 0.7 % / 0.25 deg per 100 m, our stereo VO 0.4-2.3 % / 0.2-0.9 deg per 100 m.
NOISE_LEVELS = {
    "low": NoiseLevel("low", (0.0, 0.01), (0.0, 0.01), (0.0, 0.3), (0.0, 0.02)),
    "medium": NoiseLevel("medium", (0.005, 0.03), (0.01, 0.02), (0.2, 1.0), (0.02, 0.05)),
    "high": NoiseLevel("high", (0.02, 0.05), (0.02, 0.05), (1.0, 2.0), (0.05, 0.1)),
}


def _circuit(graph: RoadGraph, length_m: float, rng: np.random.Generator, tries: int = 200) -> tuple[list[int], list[int]] | None:
    """A closed walk (a cycle of distinct roads) of about ``length_m / 2``, driven twice."""
    for _ in range(tries):
        route, froms = random_route(graph, 4.0 * length_m, rng)
        nodes = list(froms)
        for i in range(len(route)):
            for j in range(i + 2, len(route)):
                if froms[j] == nodes[i] and len(set(route[i:j])) == j - i:
                    loop = float(graph.edges.length_m.iloc[route[i:j]].sum())
                    if 0.3 * length_m <= loop <= 0.7 * length_m:
                        return route[i:j] * 2, froms[i:j] * 2
    return None


def _walk(graph: RoadGraph, length_m: float, rng: np.random.Generator, attempts: int = 50) -> tuple[list[int], list[int]]:
    """The first of up to ``attempts`` random walks that reaches ``length_m`` before turning back at a dead end
    (a camera path cannot turn on the spot), else the longest."""
    best: tuple[list[int], list[int]] = ([], [])
    best_len = -1.0
    for _ in range(attempts):
        route, froms = random_route(graph, length_m, rng)
        for i in range(1, len(route)):
            if route[i] == route[i - 1]:
                route, froms = route[:i], froms[:i]
                break
        total = float(graph.edges.length_m.iloc[route].sum()) if route else 0.0
        if total > best_len:
            best, best_len = (route, froms), total
        if total >= length_m:
            break
    return best


def simulate_pattern_drive(graph: RoadGraph, length_m: float, level: NoiseLevel, rng: np.random.Generator,
                           pattern: str = "random", stop_frames: int = 600, reverse_m: float = 15.0) -> SimulatedDrive:
    """One drive of about ``length_m`` on ``graph`` driven like a car, in a pattern, noise drawn from ``level``."""
    if pattern not in PATTERNS:
        raise ValueError(f"pattern must be one of {PATTERNS}, got {pattern!r}")
    walk = _circuit(graph, length_m, rng) if pattern == "circuit" else None
    if walk is None:
        walk = _walk(graph, length_m + 20.0, rng)
    dense, labels = sample_route(graph, walk[0], walk[1], DENSE_M)
    xy, yaw, edge = smooth_path(dense, labels, 1.0, 4.0, 1.5, 3.0)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    keep = cum <= length_m
    xy, yaw, edge = xy[keep], yaw[keep], edge[keep]
    sign = np.ones(len(xy) - 1)
    if pattern == "stop_reverse" and len(xy) > 4 * reverse_m:
        xy, yaw, edge, sign = _stop_and_reverse(xy, yaw, edge, stop_frames, reverse_m)
    noise = level.draw(rng)
    odometry = integrate_odometry(xy, yaw, OdometryNoise.from_dict(noise), rng, sign)
    return SimulatedDrive(xy, yaw, edge.astype(np.int64), odometry, noise, pattern, walk[0])


def _stop_and_reverse(xy: NDArray, yaw: NDArray, edge: NDArray, stop_frames: int, reverse_m: float):
    """Halfway: stand still for ``stop_frames`` frames, back up ``reverse_m`` along the path, drive on."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    mid = int(np.searchsorted(cum, cum[-1] / 2.0))
    back = int(np.searchsorted(cum, cum[mid] - reverse_m))
    order = np.concatenate([np.arange(mid + 1), np.full(stop_frames, mid), np.arange(mid - 1, back - 1, -1),
                            np.arange(back + 1, len(xy))])
    steps = np.diff(order)
    sign = np.where(steps < 0, -1.0, 1.0)
    return xy[order], yaw[order], edge[order], sign
