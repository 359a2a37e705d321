"""Simulated drives on the road graph: ground truth and noisy odometry.

A drive is a random route (a walk over the graph that respects one-way roads
and avoids U-turns unless at a dead end) of at least ``length_m``, sampled
every ``frame_spacing_m`` along the road geometry (:mod:`topoloc.motion.route`). The ground-truth
heading is the direction of travel. Odometry integrates the true per-frame increments (distance ``ds``,
heading change ``dpsi``) through the noise model of :mod:`topoloc.motion.noise`:

* ``ds' = ds * (1 + scale_error) + N(0, (distance_noise * ds)^2)`` (constant
  scale error plus white noise proportional to the step),
* ``dpsi' = dpsi + heading_drift_deg_per_100m / 100 * ds + N(0, heading_noise_deg^2)``
  (a constant gyro-like drift per distance plus white noise per frame).

The odometry starts at the true start pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.noise import OdometryNoise, integrate_odometry
from topoloc.motion.route import random_route, sample_route


@dataclass(frozen=True)
class SimulatedDrive:
    """Map-frame ground truth ``gt_xy`` (n, 2), ``gt_yaw`` (rad from east), true ``edge_id`` per frame, odometry."""

    gt_xy: NDArray[np.float64]
    gt_yaw: NDArray[np.float64]
    edge_id: NDArray[np.int64]
    est_xy: NDArray[np.float64]
    est_yaw: NDArray[np.float64]
    route: list[int]


def simulate_drive(graph: RoadGraph, length_m: float, spacing_m: float, noise: dict[str, float], rng: np.random.Generator) -> SimulatedDrive:
    """One random drive with ground truth and odometry under the documented noise model."""
    route, froms = random_route(graph, length_m, rng)
    xy, labels = sample_route(graph, route, froms, spacing_m)
    step = np.diff(xy, axis=0)
    yaw_steps = np.arctan2(step[:, 1], step[:, 0])
    yaw = np.concatenate([yaw_steps[:1], yaw_steps])
    yaw = np.unwrap(yaw)
    odometry = integrate_odometry(xy, yaw, OdometryNoise.from_dict(noise), rng)
    return SimulatedDrive(xy, yaw, labels, xy[0] + odometry.xy, odometry.yaw, route)
