"""The oracle: how far a drive must go before the map itself allows only one answer.

For a drive whose true road is known at every frame, and a start frame, count
the walks on the map (directed, one-way roads respected, U-turns as the
connectivity allows: :mod:`topoloc.localization.connectivity`) that agree with
what the vehicle has *felt* since the start: its turns and the distances
between them. A node where the true walk turns by more than ``angle_tol_deg``
(map headings where the roads meet,
:func:`topoloc.localization.metric.lane_chains.end_headings`) is an
*observable turn*; every other node it passes (a side road joining, a split
of the road in the map) is not evidence, since the vehicle drives straight
through it. An agreeing walk

* starts anywhere on a straight stretch (every node passed within
  ``angle_tol_deg`` of straight) at least ``(1 - length_tol)`` times as long as
  the distance driven to the first observable turn;
* reaches a node where it turns by the same angle (within ``angle_tol_deg``)
  after a straight stretch whose length is within ``length_tol`` of the distance
  between two observable turns of the true walk;
* and, between turns, has at least ``(1 - length_tol)`` times the distance
  driven so far straight ahead.

Lengths and angles of the true walk are the map's own (not the odometry's), so
the count depends on the map and the route only. The distance after which
exactly one place (directed edge) is left, and stays alone for ``confirm_m``
(or to the end of the drive), is the *uniqueness limit* of the map for that
start. The evidence is turns and lengths only: the shape of a road between its
nodes (its curves) is not counted, so a localizer that matches curves can be
sure earlier.

Where the map cannot decide, the oracle says so: a start that is never left
with one place although the drive turned at least ``ambiguous_turns`` times is
``ambiguous`` (another walk fits the whole drive, such as the mirror walk of an
out-and-back on a dual carriageway: the same loop the other way round on the
other carriageway), one with fewer turns ``open``. Lengths are compared
between turns, not per map edge: where side roads join (which differs between
the two carriageways of a real dual carriageway) a vehicle cannot sense, so it
does not tell the mirror walks apart.
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
    """Per frame from the start: walks that agree (``walks``); the distance at which one is left, or NaN.

    ``status`` says what the map decides: ``resolved`` (one place left, at ``localized_m``), ``ambiguous``
    (never one place, although the drive turned at least ``ambiguous_turns`` times: another walk of the map fits
    the whole drive, a mirror walk) or ``open`` (too few turns to tell)."""

    start_frame: int
    walks: NDArray[np.float64]
    places: NDArray[np.float64]  #: distinct directed edges the agreeing walks are on
    localized_m: float
    localized_frame: int | None
    turns: int = 0  #: observable turns (more than ``angle_tol_deg``) driven from the start
    status: str = "open"


class Oracle:
    """Counts agreeing walks on one road graph (see the module docstring)."""

    def __init__(self, graph: RoadGraph, states: DirectedEdges, angle_tol_deg: float = 15.0, length_tol: float = 0.05,
                 heading_window_m: float = 20.0, ambiguous_turns: int = 2) -> None:
        self.states, self.angle_tol, self.length_tol = states, np.radians(angle_tol_deg), float(length_tol)
        self.ambiguous_turns = int(ambiguous_turns)
        self.h_start, self.h_end = end_headings(graph, states, heading_window_m / 2.0)
        self.valid = np.flatnonzero(states.valid)
        src = np.repeat(np.arange(states.num_states), np.diff(states.next_ptr))
        dst = states.next_idx
        keep = states.valid[src] & states.valid[dst]
        self.src, self.dst = src[keep], dst[keep]
        self.angle = self.turn(self.src, self.dst)
        straight = np.abs(self.angle) <= self.angle_tol
        order = np.argsort(self.src[straight], kind="stable")
        self.s_src, self.s_dst = self.src[straight][order], self.dst[straight][order]
        self.s_ptr = np.searchsorted(self.s_src, np.arange(states.num_states + 1))
        self._back: NDArray[np.float64] | None = None

    def turn(self, a: NDArray[np.int64], b: NDArray[np.int64]) -> NDArray[np.float64]:
        """Heading change (radians, counter-clockwise) from directed edge ``a`` into ``b``."""
        return np.angle(np.exp(1j * (self.h_start[b] - self.h_end[a])))

    def straight_back(self, cap: float) -> NDArray[np.float64]:
        """Per state, the longest walk that ends at its end and passes every node straight (capped at ``cap``)."""
        if self._back is None or self._back_cap < cap:
            cap = max(cap, 5000.0)  # computed once for most drives, not once per start
            length = np.where(self.states.valid, self.states.length, 0.0)
            back = np.minimum(length, cap)
            for _ in range(100_000):  # relax until nothing grows (straight loops stop at the cap)
                grown = back.copy()
                np.maximum.at(grown, self.s_dst, np.minimum(back[self.s_src] + length[self.s_dst], cap))
                if np.array_equal(grown, back):
                    break
                back = grown
            self._back, self._back_cap = back, cap
        return self._back

    def _forward(self, cand: NDArray[np.int64], mult: NDArray[np.float64], hi: float) -> tuple[NDArray, ...]:
        """Every straight walk from the starts of ``cand`` up to ``hi`` metres: per piece its candidate, state,
        metres at its start and end, and whether the walk cannot go on straight from its end."""
        st = self.states
        owner, state, begin = np.arange(len(cand)), cand.copy(), np.zeros(len(cand))
        pieces = []
        for _ in range(100_000):
            if len(state) == 0:
                break
            end = begin + st.length[state]
            counts = self.s_ptr[state + 1] - self.s_ptr[state]
            pieces.append((owner, state, begin, end, counts == 0))
            go = (end < hi) & (counts > 0)
            owner, state, end, counts = owner[go], state[go], end[go], counts[go]
            idx = np.repeat(self.s_ptr[state], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
            owner, begin, state = np.repeat(owner, counts), np.repeat(end, counts), self.s_dst[idx]
        return tuple(np.concatenate([p[i] for p in pieces]) for i in range(5))

    def _coverage(self, d: NDArray[np.float64], state, begin, end, weight) -> tuple[NDArray, NDArray]:
        """Walks (summed ``weight``) and distinct states whose piece ``[begin, end)`` holds each distance ``d``."""
        walks = np.zeros(len(d) + 1)
        np.add.at(walks, np.searchsorted(d, begin), weight)
        np.add.at(walks, np.searchsorted(d, end), -weight)
        order = np.lexsort((begin, state))
        state, begin, end = state[order], begin[order], end[order]
        span = float(max(end.max(initial=0.0), 1.0)) * 2.0 + 1.0
        reach = np.maximum.accumulate(state * span + end) - state * span
        new = np.ones(len(state), bool)
        new[1:] = (state[1:] != state[:-1]) | (begin[1:] > reach[:-1])
        group = np.cumsum(new) - 1
        lo, hi = begin[new], np.zeros(new.sum())
        np.maximum.at(hi, group, end)
        places = np.zeros(len(d) + 1)
        np.add.at(places, np.searchsorted(d, lo), 1.0)
        np.add.at(places, np.searchsorted(d, hi), -1.0)
        return np.cumsum(walks)[:-1], np.cumsum(places)[:-1]

    def count(self, path: TruePath, start: int, confirm_m: float) -> OracleResult:
        """Agreeing walks at every frame from ``start`` on, and the distance driven when one is left."""
        length, tol = self.states.length, self.length_tol
        run_start, run_of = path.runs()
        n = len(path.state)
        k0 = int(run_of[start])
        # map metres from the start at every frame, and the observable turns (events) of the true walk
        firsts = np.append(run_start[k0 + 1:], n)
        base = np.zeros(len(firsts))
        driven_run = length[path.state[firsts - 1]]
        driven_run[0] -= path.offset[start]
        base[1:] = np.cumsum(driven_run)[:-1]
        frames = np.arange(start, n)
        rel = run_of[frames] - k0
        mapd = base[rel] + path.offset[frames] - np.where(rel == 0, path.offset[start], 0.0)
        mapd = np.maximum.accumulate(np.maximum(mapd, 0.0))
        cross = firsts[:-1]
        angles = self.turn(path.state[cross - 1], path.state[cross]) if len(cross) else np.zeros(0)
        event = np.abs(angles) > self.angle_tol
        ev_at, ev_angle = base[1:][event], angles[event]
        walks, places = np.zeros(n - start), np.zeros(n - start)
        bounds = np.concatenate([[0.0], ev_at, [np.inf]])
        seg = np.searchsorted(bounds, mapd, side="right") - 1  # the segment between events of every frame
        cand = mult = None
        for k in range(len(bounds) - 1):
            d = mapd[seg == k] - bounds[k]
            seg_len = bounds[k + 1] - bounds[k]
            if k == 0:  # any straight walk long enough may have led here
                back = self.straight_back(float(ev_at[0]) * (1 + tol) + 1.0 if len(ev_at) else float(mapd[-1]) + 1.0)
                need = (1.0 - tol) * d
                order = np.sort(back[self.valid])
                walks[seg == k] = places[seg == k] = len(order) - np.searchsorted(order, need)
                if len(ev_at) == 0:
                    break
                ok = (np.abs(np.angle(np.exp(1j * (self.angle - ev_angle[0])))) <= self.angle_tol) & (back[self.src] >= (1.0 - tol) * seg_len)
                cand, mult = self._merge(self.dst[ok], np.ones(ok.sum()))
                if len(cand) == 0:  # no road of the map turns as the drive does (the map lacks the true turn)
                    break
                continue
            hi = (1.0 + tol) * seg_len if np.isfinite(seg_len) else float(d.max(initial=0.0)) + 1.0
            owner, state, begin, end, stuck = self._forward(cand, mult, hi)
            reach = np.where(stuck, end / (1.0 - tol) if tol < 1 else np.inf, end)
            if len(d):
                walks[seg == k], places[seg == k] = self._coverage(d, state, begin, reach, mult[owner])
            if not np.isfinite(seg_len):
                break
            at = (end >= (1.0 - tol) * seg_len) & (end <= (1.0 + tol) * seg_len)
            o_idx, s_idx = np.flatnonzero(at), state[at]
            counts = np.diff(self.states.next_ptr)[s_idx]
            src_rep = np.repeat(o_idx, counts)
            nxt_idx = np.repeat(self.states.next_ptr[s_idx], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
            nxt = self.states.next_idx[nxt_idx]
            good = np.abs(np.angle(np.exp(1j * (self.turn(state[src_rep], nxt) - ev_angle[k])))) <= self.angle_tol
            cand, mult = self._merge(nxt[good], mult[owner[src_rep[good]]])
            if len(cand) == 0:
                break
        localized = _first_unique(places, path.driven[start:], confirm_m)
        turns = int(event.sum())
        if localized is None:
            status = "ambiguous" if turns >= self.ambiguous_turns and places[-1] >= 2 else "open"
            return OracleResult(start, walks, places, float("nan"), None, turns, status)
        return OracleResult(start, walks, places, float(path.driven[start + localized] - path.driven[start]),
                            start + localized, turns, "resolved")

    @staticmethod
    def _merge(states: NDArray[np.int64], mult: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Walks that reach the same directed edge's start are one place: their counts add up."""
        if len(states) == 0:
            return states.astype(np.int64), mult
        uniq, inverse = np.unique(states, return_inverse=True)
        return uniq, np.bincount(inverse, weights=mult)


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
