"""Simulated drives on the road graph: ground truth and noisy odometry.

A drive is a random route (a walk over the graph that respects one-way roads
and avoids U-turns unless at a dead end) of at least ``length_m``, sampled
every ``frame_spacing_m`` along the road geometry. The ground-truth heading is
the direction of travel. Odometry integrates the true per-frame increments
(distance ``ds``, heading change ``dpsi``) through this noise model:

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


@dataclass(frozen=True)
class SimulatedDrive:
    """Map-frame ground truth ``gt_xy`` (n, 2), ``gt_yaw`` (rad from east), true ``edge_id`` per frame, odometry."""

    gt_xy: NDArray[np.float64]
    gt_yaw: NDArray[np.float64]
    edge_id: NDArray[np.int64]
    est_xy: NDArray[np.float64]
    est_yaw: NDArray[np.float64]
    route: list[int]


def random_route(graph: RoadGraph, length_m: float, rng: np.random.Generator, max_steps: int = 10000) -> tuple[list[int], list[int]]:
    """A random walk of edges (and the node each is entered from) of total length at least ``length_m``."""
    edges = graph.edges
    g = graph.graph
    nodes = [n for n in graph.nodes.index if graph.nodes.degree.at[n] >= 2] or list(graph.nodes.index)
    node = int(rng.choice(nodes))
    route: list[int] = []
    froms: list[int] = []
    total = 0.0
    for _ in range(max_steps):
        options = []
        for _, other, key in g.edges(node, keys=True):
            ow = edges.oneway.iat[key]
            if ow == 1 and edges.u.iat[key] != node or ow == -1 and edges.v.iat[key] != node:
                continue
            if route and key == route[-1] and g.degree(node) > 1:
                continue
            options.append(key)
        if not options:
            options = [route[-1]] if route else []
        if not options:
            break
        key = int(rng.choice(options))
        route.append(key)
        froms.append(node)
        total += float(edges.length_m.iat[key])
        node = graph.other_end(key, node)
        if total >= length_m:
            break
    return route, froms


def sample_route(graph: RoadGraph, route: list[int], froms: list[int], spacing_m: float) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Points every ``spacing_m`` along the route, and the edge of each."""
    pieces = [graph.edge_coords(e, f) for e, f in zip(route, froms)]
    coords = [pieces[0][:1]]
    labels = [np.array([route[0]])]
    for e, piece in zip(route, pieces):
        coords.append(piece[1:])
        labels.append(np.full(len(piece) - 1, e))
    pts = np.concatenate(coords)
    lab = np.concatenate(labels)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-6])
    pts, lab = pts[keep], lab[keep]
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    s = np.arange(0.0, cum[-1], spacing_m)
    x = np.interp(s, cum, pts[:, 0])
    y = np.interp(s, cum, pts[:, 1])
    idx = np.clip(np.searchsorted(cum, s, side="right"), 1, len(cum) - 1)
    return np.column_stack([x, y]), lab[idx].astype(np.int64)


def simulate_drive(graph: RoadGraph, length_m: float, spacing_m: float, noise: dict[str, float], rng: np.random.Generator) -> SimulatedDrive:
    """One random drive with ground truth and odometry under the documented noise model."""
    route, froms = random_route(graph, length_m, rng)
    xy, labels = sample_route(graph, route, froms, spacing_m)
    step = np.diff(xy, axis=0)
    yaw_steps = np.arctan2(step[:, 1], step[:, 0])
    yaw = np.concatenate([yaw_steps[:1], yaw_steps])
    yaw = np.unwrap(yaw)
    ds = np.hypot(step[:, 0], step[:, 1])
    dpsi = np.diff(yaw)
    ds_est = ds * (1.0 + noise["scale_error"]) + rng.normal(0.0, 1.0, len(ds)) * noise["distance_noise"] * ds
    dpsi_est = (dpsi + np.radians(noise["heading_drift_deg_per_100m"]) / 100.0 * ds
                + np.radians(noise["heading_noise_deg"]) * rng.normal(0.0, 1.0, len(ds)))
    est_yaw = yaw[0] + np.concatenate([[0.0], np.cumsum(dpsi_est)])
    # The step from frame k to k+1 is taken along the heading of frame k+1, as the truth does.
    moves = ds_est[:, None] * np.column_stack([np.cos(est_yaw[1:]), np.sin(est_yaw[1:])])
    est_xy = xy[0] + np.concatenate([np.zeros((1, 2)), np.cumsum(moves, axis=0)])
    return SimulatedDrive(xy, yaw, labels, est_xy, est_yaw, route)
