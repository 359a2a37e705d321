"""Frame labels: map-match a georeferenced track to road edges as a connected edge sequence.

A hidden Markov model over candidate edges (those within ``radius_m`` of each
frame, plus the nearest one) solved by Viterbi:

* emission cost ``(d / sigma)^2 / 2`` for distance ``d`` to the edge, plus a
  heading term ``(1 - |cos a|) * heading_weight`` for the angle ``a`` between
  the direction of travel and the road (only while the vehicle moves);
* transition cost 0 to stay on an edge, ``switch_cost`` to move to an edge that
  shares an end node with it, ``jump_cost`` (large) otherwise, so the result is
  connected unless the track leaves the graph; such jumps are counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph


@dataclass(frozen=True)
class MatchResult:
    """Per-frame ``edge_id``, distance to it, and the number of unconnected edge changes."""

    edge_id: NDArray[np.int64]
    distance_m: NDArray[np.float64]
    jumps: int


def _travel_direction(xy: NDArray[np.float64], reach: int = 3) -> NDArray[np.float64]:
    n = len(xy)
    idx = np.arange(n)
    d = xy[np.minimum(idx + reach, n - 1)] - xy[np.maximum(idx - reach, 0)]
    norm = np.hypot(d[:, 0], d[:, 1])
    out = np.zeros_like(d)
    moving = norm > 0.5
    out[moving] = d[moving] / norm[moving, None]
    return out


def match_track(graph: RoadGraph, xy: NDArray[np.float64], radius_m: float = 25.0, sigma_m: float = 5.0,
                heading_weight: float = 4.0, switch_cost: float = 1.0, jump_cost: float = 200.0) -> MatchResult:
    """Label each point of the map-frame track ``xy`` (n, 2) with an edge id (connected Viterbi path)."""
    xy = np.asarray(xy, float)
    n = len(xy)
    lines = np.array([shapely.LineString(g) for g in graph.geometry], dtype=object)
    tree = shapely.STRtree(lines)
    points = shapely.points(xy)
    pi, ei = tree.query(points, predicate="dwithin", distance=radius_m)
    near = tree.query_nearest(points, all_matches=False)
    pi = np.concatenate([pi, near[0]])
    ei = np.concatenate([ei, near[1]])
    pairs = np.unique(np.column_stack([pi, ei]), axis=0)
    pi, ei = pairs[:, 0], pairs[:, 1]
    dist = shapely.distance(points[pi], lines[ei])
    s = shapely.line_locate_point(lines[ei], points[pi])
    a = shapely.get_coordinates(shapely.line_interpolate_point(lines[ei], np.maximum(s - 2.0, 0.0)))
    b = shapely.get_coordinates(shapely.line_interpolate_point(lines[ei], s + 2.0))
    tangent = b - a
    tangent /= np.maximum(np.hypot(tangent[:, 0], tangent[:, 1]), 1e-9)[:, None]
    travel = _travel_direction(xy)[pi]
    moving = np.hypot(travel[:, 0], travel[:, 1]) > 0
    cos = np.abs(np.sum(tangent * travel, axis=1))
    emission = 0.5 * (dist / sigma_m) ** 2 + np.where(moving, (1.0 - cos) * heading_weight, 0.0)

    starts = np.searchsorted(pi, np.arange(n + 1))
    u = graph.edges.u.to_numpy()
    v = graph.edges.v.to_numpy()
    cost = emission[starts[0]:starts[1]].copy()
    back: list[NDArray[np.int64]] = []
    for k in range(1, n):
        prev = ei[starts[k - 1]:starts[k]]
        cur = ei[starts[k]:starts[k + 1]]
        same = prev[:, None] == cur[None, :]
        adjacent = ((u[prev][:, None] == u[cur][None, :]) | (u[prev][:, None] == v[cur][None, :])
                    | (v[prev][:, None] == u[cur][None, :]) | (v[prev][:, None] == v[cur][None, :]))
        trans = np.where(same, 0.0, np.where(adjacent, switch_cost, jump_cost))
        total = cost[:, None] + trans
        arg = np.argmin(total, axis=0)
        back.append(arg)
        cost = total[arg, np.arange(len(cur))] + emission[starts[k]:starts[k + 1]]
    path = np.empty(n, dtype=np.int64)
    j = int(np.argmin(cost))
    path[n - 1] = j
    for k in range(n - 1, 0, -1):
        j = int(back[k - 1][j])
        path[k - 1] = j
    rows = starts[:-1] + path
    edge = ei[rows].astype(np.int64)
    jumps = 0
    for e0, e1 in zip(edge[:-1], edge[1:]):
        if e0 != e1 and not ({u[e0], v[e0]} & {u[e1], v[e1]}):
            jumps += 1
    return MatchResult(edge, dist[rows], jumps)
