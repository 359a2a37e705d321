"""The oracle: how far a drive must go before the map itself allows only one answer.

For a drive whose true road is known at every frame, and a start frame, count
the walks on the map (directed, one-way roads respected, U-turns as the
connectivity allows: :mod:`topoloc.localization.connectivity`) that agree with
what the vehicle has driven since the start:

* the first road partly: a candidate road is at least ``(1 - length_tol)``
  times as long as the part of the true road driven so far, and when the true
  road ends, at least as long as the part of it that was driven;
* every later road whole: when the vehicle leaves it, the candidate's length
  is within ``length_tol`` of the true road's; while on it, the candidate is
  at least ``(1 - length_tol)`` times the distance driven on it;
* every node passed: the candidate turns by the same angle as the true walk
  within ``angle_tol_deg`` (map headings where the roads meet,
  :func:`topoloc.localization.metric.lane_chains.end_headings`).

Lengths and angles of the true walk are the map's own (not the odometry's), so
the count depends on the map and the route only. The distance after which
exactly one walk agrees, and keeps agreeing alone for ``confirm_m`` (or to the
end of the drive), is the *uniqueness limit* of the map for that start: no
localizer that sees only the motion can be sure earlier.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.connectivity import DirectedEdges
from topoloc.localization.metric.lane_chains import end_headings


@dataclass(frozen=True)
class TruePath:
    """The true walk of a drive, per frame: directed edge (``state``), metres along it, metres driven."""

    state: NDArray[np.int64]
    offset: NDArray[np.float64]
    driven: NDArray[np.float64]

    def runs(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """First frame of every run of one directed edge, and the run of every frame."""
        starts = np.concatenate([[0], np.flatnonzero(np.diff(self.state) != 0) + 1])
        return starts, np.repeat(np.arange(len(starts)), np.diff(np.append(starts, len(self.state))))


def _shared_node(graph: RoadGraph, a: int, b: int) -> int | None:
    ends_a = {int(graph.edges.u.iat[a]), int(graph.edges.v.iat[a])}
    ends_b = {int(graph.edges.u.iat[b]), int(graph.edges.v.iat[b])}
    shared = ends_a & ends_b
    return next(iter(shared)) if len(shared) == 1 else None


def true_path(graph: RoadGraph, edge: NDArray[np.int64], xy: NDArray[np.float64], driven: NDArray[np.float64]) -> TruePath:
    """The directed true walk from per-frame road labels ``edge`` and map positions ``xy`` (ground truth)."""
    edge = np.asarray(edge, np.int64)
    xy = np.asarray(xy, float)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(edge) != 0) + 1])
    ends = np.append(starts[1:], len(edge))
    lines = [shapely.LineString(graph.geometry[e]) for e in range(graph.num_edges)]
    along = np.empty(len(edge))
    forward = np.empty(len(starts), bool)
    for k, (a, b) in enumerate(zip(starts, ends)):
        e = int(edge[a])
        along[a:b] = shapely.line_locate_point(lines[e], shapely.points(xy[a:b]))
        node_next = _shared_node(graph, e, int(edge[b])) if b < len(edge) else None
        node_prev = _shared_node(graph, int(edge[a - 1]), e) if a > 0 else None
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        if node_next is not None and u != v:
            forward[k] = node_next == v
        elif node_prev is not None and u != v:
            forward[k] = node_prev == u
        else:  # a drive on one road, or ambiguous ends: the direction the positions move in
            forward[k] = along[b - 1] >= along[a]
    length = graph.edges.length_m.to_numpy(float)
    run_of = np.repeat(np.arange(len(starts)), ends - starts)
    fwd = forward[run_of]
    state = 2 * edge + (~fwd).astype(np.int64)
    offset = np.where(fwd, along, length[edge] - along)
    return TruePath(state, np.clip(offset, 0.0, length[edge]), np.asarray(driven, float))


@dataclass(frozen=True)
class OracleResult:
    """Per frame from the start: walks that agree (``walks``); the distance at which one is left, or NaN."""

    start_frame: int
    walks: NDArray[np.float64]
    places: NDArray[np.float64]  #: distinct directed edges the agreeing walks are on
    localized_m: float
    localized_frame: int | None


class Oracle:
    """Counts agreeing walks on one road graph (see the module docstring)."""

    def __init__(self, graph: RoadGraph, states: DirectedEdges, angle_tol_deg: float = 15.0, length_tol: float = 0.05,
                 heading_window_m: float = 20.0) -> None:
        self.states, self.angle_tol, self.length_tol = states, np.radians(angle_tol_deg), float(length_tol)
        self.h_start, self.h_end = end_headings(graph, states, heading_window_m / 2.0)
        self.valid = np.flatnonzero(states.valid)

    def turn(self, a: NDArray[np.int64], b: NDArray[np.int64]) -> NDArray[np.float64]:
        """Heading change (radians, counter-clockwise) from directed edge ``a`` into ``b``."""
        return np.angle(np.exp(1j * (self.h_start[b] - self.h_end[a])))

    def _expand(self, cand: NDArray[np.int64], mult: NDArray[np.float64], turn: float) -> tuple[NDArray, NDArray]:
        st = self.states
        counts = st.next_ptr[cand + 1] - st.next_ptr[cand]
        owner = np.repeat(np.arange(len(cand)), counts)
        idx = np.repeat(st.next_ptr[cand], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        nxt = st.next_idx[idx]
        ok = np.abs(np.angle(np.exp(1j * (self.turn(cand[owner], nxt) - turn)))) <= self.angle_tol
        nxt, weights = nxt[ok], mult[owner][ok]
        if len(nxt) == 0:
            return nxt, weights
        states, inverse = np.unique(nxt, return_inverse=True)
        return states, np.bincount(inverse, weights=weights)

    def count(self, path: TruePath, start: int, confirm_m: float) -> OracleResult:
        """Agreeing walks at every frame from ``start`` on, and the distance driven when one is left."""
        length = self.states.length
        tol = self.length_tol
        run_start, run_of = path.runs()
        n = len(path.state)
        walks = np.zeros(n - start)
        places = np.zeros(n - start)
        cand, mult = self.valid, np.ones(len(self.valid))
        k0 = run_of[start]
        for k in range(k0, len(run_start)):
            a = max(int(run_start[k]), start)
            b = int(run_start[k + 1]) if k + 1 < len(run_start) else n
            on = path.offset[a:b] - (path.offset[start] if k == k0 else 0.0)
            order = np.argsort(length[cand])
            sorted_len, cum = length[cand][order], np.concatenate([[0.0], np.cumsum(mult[order])])
            first = np.searchsorted(sorted_len, (1.0 - tol) * np.maximum(on, 0.0))
            walks[a - start:b - start] = cum[-1] - cum[first]
            places[a - start:b - start] = len(cand) - first
            if b == n:
                break
            true_state, next_state = int(path.state[b - 1]), int(path.state[b])
            driven = length[true_state] - (path.offset[start] if k == k0 else 0.0)
            if k == k0:
                keep = length[cand] >= (1.0 - tol) * driven
            else:
                keep = np.abs(length[cand] - driven) <= tol * driven
            cand, mult = self._expand(cand[keep], mult[keep], float(self.turn(np.array([true_state]), np.array([next_state]))[0]))
            if len(cand) == 0:
                walks[b - start:] = 0.0
                places[b - start:] = 0.0
                break
        localized = _first_unique(places, path.driven[start:], confirm_m)
        if localized is None:
            return OracleResult(start, walks, places, float("nan"), None)
        return OracleResult(start, walks, places, float(path.driven[start + localized] - path.driven[start]), start + localized)


def _first_unique(count: NDArray[np.float64], driven: NDArray[np.float64], confirm_m: float) -> int | None:
    """First index where one walk is left and stays alone for ``confirm_m`` metres or to the end."""
    unique = np.abs(count - 1.0) < 1e-9
    if not unique.any():
        return None
    breaks = np.flatnonzero(~unique)
    for t in np.flatnonzero(unique & np.concatenate([[True], ~unique[:-1]])):
        later = breaks[breaks > t]
        end = int(later[0]) if len(later) else len(count)
        if end == len(count) or driven[end - 1] - driven[t] >= confirm_m:
            return int(t)
    return None
