"""Positions on a road network as cells of *chains*, and how they move.

A chain is a stretch of road that a vehicle drives from its start to its end:
a directed edge (a road in a direction its one-way tag allows, see
:mod:`topoloc.localization.connectivity`), or, for the metric filter, a piece
of one (:mod:`topoloc.localization.metric.lane_chains`: the middle of a road, or a *turn*
from the end of one road into the start of the next). A chain lies on at most
two directed edges: it starts ``first_from`` metres into ``first_state`` and,
``split`` metres further, may pass the node into ``second_state``. Its
``length`` is what a vehicle drives along it; a turn may be shorter than its
path on the map through the node (a car cuts the corner on an arc: ``stretch``,
map metres per metre driven), and its cells map driven metres onto the map in
proportion.

Every chain is cut into ``ceil(length / cell_m)`` cells of equal length; a cell
stands for its centre. Per cell the grid knows its chain, its directed edge,
its offset along both, its road (undirected edge), its map position (on the
centreline, or ``lane_offset_m`` to the right of its direction: :func:`lane_offsets`) and the
road's heading there: the chord over ``heading_window_m`` around it, clipped to
its directed edge (so a cell next to an intersection has the heading with
which its road meets it), turned on turn chains by the share of the turn a
vehicle has made at that point (a smooth step through the node).

:meth:`CellGrid.moves` lists, for a drive of ``D`` metres from every cell, the
cells where the vehicle lands and with which probability: along the chain,
then onto every chain that may follow (equal shares, or by the chains' ``weight``), hop after hop; a
landing point between two cell centres is split between them (linear
interpolation). Both localizers on cells (the token HMM baseline and the
metric filter) build their transitions from it.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.connectivity import DirectedEdges
from topoloc.render.textures import edge_widths

MAX_HOPS = 64
#: Where a vehicle keeps across a road (``localization.places.lane``): the sign of its offset to the right.
LANE_SIDES = {"right": 1.0, "left": -1.0, "centre": 0.0}


@dataclass(frozen=True)
class Chains:
    """Chains of a road network (see the module docstring); successors as CSR lists ``next_ptr``, ``next_idx``."""

    length: NDArray[np.float64]
    next_ptr: NDArray[np.int64]
    next_idx: NDArray[np.int64]
    first_state: NDArray[np.int64]
    first_from: NDArray[np.float64]
    split: NDArray[np.float64]
    second_state: NDArray[np.int64]
    turn: NDArray[np.float64]  #: heading change (radians, counter-clockwise) at the node inside the chain, else 0
    #: weight of entering this chain where several may follow one (relative to its siblings'); None: all 1
    weight: NDArray[np.float64] | None = None
    #: weight of the way the chain takes (several chains may be one way: a U-turn's two sweeps); None: ``weight``
    way: NDArray[np.float64] | None = None
    #: map metres per metre driven along the chain (> 1: a turn whose arc is shorter than the map's path through
    #: the node, :func:`topoloc.localization.metric.lane_chains.turn_arc_length`); None: 1
    stretch: NDArray[np.float64] | None = None
    #: on a turn that is a circular arc (``stretch`` set; 0 elsewhere): where the arc begins and how long it is, metres
    #: driven from the chain's start; along it the heading turns evenly
    arc_from: NDArray[np.float64] | None = None
    arc_len: NDArray[np.float64] | None = None
    #: metres driven straight at half the turn in the middle of the arc (a U-turn across a median); None: 0
    plateau: NDArray[np.float64] | None = None
    #: per chain, its way among the turns of the *plain* chains (built with neither U-turns across a median nor wide
    #: ways, counted from 0 in their order): a turn its own, a U-turn across its tight U-turn of the same sweep, a
    #: wide turn the tight turn of the same pair; -1 on the pieces of one road; None: the chains are the plain ones
    plain_turn: NDArray[np.int64] | None = None

    @property
    def num_chains(self) -> int:
        return len(self.length)

    @property
    def map_length(self) -> NDArray[np.float64]:
        """Per chain, its length on the map (``length`` is what a vehicle drives)."""
        return self.length if self.stretch is None else self.length * self.stretch

    @classmethod
    def of_states(cls, states: DirectedEdges) -> Chains:
        """One chain per valid directed edge (the cells of the token HMM); invalid states have no cells."""
        valid = states.valid
        n = states.num_states
        return cls(np.where(valid, states.length, 0.0), states.next_ptr, states.next_idx, np.arange(n),
                   np.zeros(n), states.length.copy(), np.full(n, -1), np.zeros(n))


def polyline_headings(coords: NDArray[np.float64], positions: NDArray[np.float64], half: float) -> NDArray[np.float64]:
    """Travel heading (degrees, counter-clockwise from +x) of a polyline at ``positions`` over +-``half`` metres."""
    seg = np.hypot(*np.diff(coords, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    a = np.clip(positions - half, 0.0, cum[-1])
    b = np.clip(positions + half, 0.0, cum[-1])
    b = np.where(b - a < 1e-6, np.minimum(a + 1e-3, cum[-1]), b)
    a = np.where(b - a < 1e-6, np.maximum(b - 1e-3, 0.0), a)
    dx = np.interp(b, cum, coords[:, 0]) - np.interp(a, cum, coords[:, 0])
    dy = np.interp(b, cum, coords[:, 1]) - np.interp(a, cum, coords[:, 1])
    return np.degrees(np.arctan2(dy, dx))


def lane_offsets(graph: RoadGraph, side: str) -> NDArray[np.float64]:
    """Per directed edge (state ``2 e`` runs u -> v, ``2 e + 1`` v -> u), metres to the right of the centreline where a
    vehicle driving it keeps: on a two-way road a quarter of its carriageway (the middle of the lanes one way:
    :func:`topoloc.render.textures.carriageway_width`), to the right in right-hand traffic (``side`` ``right``), to the
    left in left-hand traffic (``left``: negative); on a one-way road, and with ``centre``, the centreline (0)."""
    if side not in LANE_SIDES:
        raise InputError("localization.places.lane", f"must be one of {list(LANE_SIDES)}, got {side!r}")
    if LANE_SIDES[side] == 0:  # the default: no widths to work out (a Python loop over a city's roads)
        return np.zeros(2 * graph.num_edges)
    two_way = graph.edges.oneway.to_numpy() == 0
    offset = np.where(two_way, LANE_SIDES[side] * edge_widths(graph.edges) / 4.0, 0.0)
    return np.repeat(offset, 2)


def state_coords(graph: RoadGraph, state: int) -> NDArray[np.float64]:
    """Polyline of a directed edge (state ``2 e`` runs u -> v, ``2 e + 1`` v -> u)."""
    coords = np.asarray(graph.geometry[state // 2], float)
    return coords if state % 2 == 0 else coords[::-1]


@dataclass(frozen=True)
class Moves:
    """Sparse moves of one drive distance: from cell ``src`` to cell ``dst`` with probability ``weight``."""

    src: NDArray[np.int64]
    dst: NDArray[np.int64]
    weight: NDArray[np.float64]


class CellGrid:
    """Cells of at most ``cell_m`` metres on every chain of a road graph.

    Attributes, one entry per cell: ``chain``, ``offset`` (metres from the chain's start to the cell
    centre, driven metres), ``state`` (directed edge), ``state_offset`` (metres along it), ``edge`` (road id), ``xy``
    (map position: ``lane_offset_m[state]`` right of the centreline, if given), ``heading`` (degrees
    counter-clockwise from +x) and ``to_node`` (metres to the nearest end of its directed edge); per chain:
    ``base`` (its first cell) and ``cell_len``. Only the answers' positions use ``xy``; the filters move and weigh
    cells by chain, offset and heading.
    """

    def __init__(self, graph: RoadGraph, states: DirectedEdges, chains: Chains, cell_m: float,
                 heading_window_m: float, lane_offset_m: NDArray[np.float64] | None = None) -> None:
        if not cell_m > 0:
            raise ValueError(f"cell_m must be positive, got {cell_m}")
        self.states, self.chains, self.cell_m = states, chains, float(cell_m)
        has = chains.length > 0
        counts = np.zeros(chains.num_chains, np.int64)
        counts[has] = np.maximum(1, np.ceil(chains.length[has] / cell_m - 1e-9)).astype(np.int64)
        self.cell_len = np.where(counts > 0, chains.length / np.maximum(counts, 1), 0.0)
        self.base = np.concatenate([[0], np.cumsum(counts)])
        self.chain = np.repeat(np.arange(chains.num_chains), counts)
        self.offset = (np.arange(len(self.chain)) - self.base[self.chain] + 0.5) * self.cell_len[self.chain]
        on_map = self.offset if chains.stretch is None else self.offset * chains.stretch[self.chain]
        since_node = on_map - chains.split[self.chain]  # map metres past the node inside the chain (< 0 before)
        second = (since_node >= 0) & (chains.second_state[self.chain] >= 0)
        self.state = np.where(second, chains.second_state[self.chain], chains.first_state[self.chain])
        self.state_offset = np.where(second, since_node, chains.first_from[self.chain] + on_map)
        self.edge = states.edge[self.state]
        self.num_roads = states.num_edges  # the roads ``edge`` names (fewer where roads were added to the map)
        self.xy, plain = self._geometry(graph, heading_window_m / 2.0, lane_offset_m)
        self.heading = plain + np.degrees(self._turned_share(since_node, second) * chains.turn[self.chain])
        self.turn_ramp = self._ramp(since_node)
        self.prior = self._prior(second)

    def _prior(self, second: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Uniform over road length: a stretch of road covered by several turn chains shares its length."""
        ch = self.chains
        turns = ch.second_state >= 0
        leaving = np.bincount(ch.first_state[turns], minlength=self.states.num_states)
        entering = np.bincount(ch.second_state[turns], minlength=self.states.num_states)
        coverage = np.where(second, entering[self.state], np.where(turns[self.chain], leaving[self.state], 1))
        prior = self.cell_len[self.chain] * self._stretch / np.maximum(coverage, 1)
        return prior / prior.sum()

    @property
    def _stretch(self) -> NDArray[np.float64] | float:
        return 1.0 if self.chains.stretch is None else self.chains.stretch[self.chain]

    def _cells_by_state(self) -> Iterator[tuple[int, NDArray[np.int64]]]:
        """Each directed edge that has cells, with its cells."""
        order = np.argsort(self.state, kind="stable")
        bounds = np.searchsorted(self.state[order], np.arange(self.states.num_states + 1))
        for s in np.flatnonzero(np.diff(bounds)):
            yield int(s), order[bounds[s]:bounds[s + 1]]

    def _geometry(self, graph: RoadGraph, half: float,
                  lane_offset_m: NDArray[np.float64] | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        xy = np.empty((self.num_cells, 2))
        heading = np.empty(self.num_cells)
        for s, cells in self._cells_by_state():
            coords = state_coords(graph, s)
            pos = self.state_offset[cells]
            cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
            xy[cells] = np.column_stack([np.interp(pos, cum, coords[:, 0]), np.interp(pos, cum, coords[:, 1])])
            heading[cells] = polyline_headings(coords, pos, half)
            if lane_offset_m is not None and lane_offset_m[s] != 0:
                h = np.radians(heading[cells])
                xy[cells] += lane_offset_m[s] * np.column_stack([np.sin(h), -np.cos(h)])
        return xy, heading

    def bend_ramp(self, graph: RoadGraph, half: float) -> NDArray[np.float64]:
        """Per cell, the turn of the bends inside its road (radians; a vertex of the road's polyline) weighed like a
        turn chain's :attr:`turn_ramp`: each bend's signed angle, 1 at the vertex, 0 ``half`` metres from it, summed
        (so a curve counts its turn within ``half`` metres, and a zigzag of a noisy polyline cancels), then absolute."""
        ramp = np.zeros(self.num_cells)
        for s, cells in self._cells_by_state():
            coords = state_coords(graph, s)
            if len(coords) < 3:
                continue
            seg = np.diff(coords, axis=0)
            length = np.hypot(*seg.T)
            keep = length > 0.1  # repeated points turn nowhere
            heading = np.arctan2(seg[keep, 1], seg[keep, 0])
            if len(heading) < 2:
                continue
            angle = (np.diff(heading) + np.pi) % (2.0 * np.pi) - np.pi  # signed: a polyline's zigzag cancels out
            at = np.cumsum(length)[keep][:-1]  # each bend: the end of the segment before it
            near = np.clip(1.0 - np.abs(self.state_offset[cells, None] - at[None, :]) / half, 0.0, 1.0)
            ramp[cells] = np.abs(near @ angle)
        return ramp

    def _ramp(self, since_node: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per cell, the turn of its chain (radians) weighed by nearness to the node: 1 at the node, 0 at the
        ends of the turn (cells of middles: 0)."""
        ch = self.chains
        before = ch.split[self.chain]
        half = np.maximum(np.minimum(before, ch.map_length[self.chain] - before), 1e-9)
        near = np.clip(1.0 - np.abs(since_node) / half, 0.0, 1.0)
        ramp = np.where(ch.second_state[self.chain] >= 0, near * np.abs(ch.turn[self.chain]), 0.0)
        if ch.plateau is None:
            return ramp
        # a U-turn across a median is two quarter turns with a straight between: each weighs as a turn of its own
        quarter = ch.arc_len[self.chain] / 2.0
        second_mid = 1.5 * quarter + ch.plateau[self.chain]
        half_q = np.maximum(quarter / 2.0, 1e-9)
        near_q = np.maximum(np.clip(1.0 - np.abs(self.offset - quarter / 2.0) / half_q, 0.0, 1.0),
                            np.clip(1.0 - np.abs(self.offset - second_mid) / half_q, 0.0, 1.0))
        return np.where(ch.plateau[self.chain] > 0, near_q * np.abs(ch.turn[self.chain]) / 2.0, ramp)

    def _turned_share(self, since_node: NDArray[np.float64], second: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Share of the chain's turn still to come (< 0 after the node: the part not yet made), per cell."""
        ch = self.chains
        before = ch.split[self.chain]
        after = ch.map_length[self.chain] - before
        half = np.maximum(np.minimum(before, after), 1e-9)
        made = 0.5 + 0.5 * np.sin(0.5 * np.pi * np.clip(since_node / half, -1.0, 1.0))
        if ch.arc_len is not None:  # a circular arc: the heading turns evenly with the distance driven along it
            arc = ch.arc_len[self.chain]
            along = self.offset - ch.arc_from[self.chain]
            if ch.plateau is not None:  # half the turn, then straight over the plateau, then the other half
                along = along - np.clip(along - arc / 2.0, 0.0, ch.plateau[self.chain])
            even = np.clip(along / np.maximum(arc, 1e-9), 0.0, 1.0)
            made = np.where(arc > 0, even, made)
        share = np.where(second, made - 1.0, made)
        return np.where(ch.second_state[self.chain] >= 0, share, 0.0)

    @property
    def num_cells(self) -> int:
        return len(self.chain)

    @cached_property
    def u_turn_chain(self) -> NDArray[np.bool_]:
        """Per chain, whether it is a U-turn: the metric filter's U-turn chains turn by exactly 180 deg either way
        (:func:`~topoloc.localization.metric.lane_chains.lane_chains`); the token HMM's chains carry no turn, so
        its moves, one road at a time, are not limited."""
        return np.abs(self.chains.turn) > np.pi - 1e-6

    @cached_property
    def to_node(self) -> NDArray[np.float64]:
        """Metres from each cell centre to the nearer end of its directed edge."""
        return np.minimum(self.state_offset, self.states.length[self.state] - self.state_offset)

    def moves(self, distance_m: float, split: bool = True) -> Moves:
        """Where a drive of ``distance_m`` (> 0) from every cell centre lands (see the module docstring); at a
        chain's end the weight is split among the chains that follow (``split``), or each keeps it whole. A move
        takes at most one U-turn (but where a dead end leaves no other way): on roads shorter than a step, U-turn
        after U-turn would bounce between two nodes, each bounce branching, without driving any distance."""
        ch = self.chains
        src = np.arange(self.num_cells)
        c = self.chain.copy()
        q = self.offset + float(distance_m)
        w = np.ones(self.num_cells)
        is_u = self.u_turn_chain
        turned = is_u[c]
        out: list[tuple[NDArray, NDArray, NDArray]] = []
        for _ in range(MAX_HOPS):  # hops across chains; stops when every move has landed
            inside = q < ch.length[c]
            if inside.any():
                out.extend(self._land(src[inside], c[inside], q[inside], w[inside]))
            leave = ~inside
            if not leave.any():
                break
            src, c, q, w, turned = src[leave], c[leave], q[leave] - ch.length[c[leave]], w[leave], turned[leave]
            counts = ch.next_ptr[c + 1] - ch.next_ptr[c]
            rep = np.repeat(np.arange(len(c)), counts)
            offset = np.arange(len(rep)) - np.repeat(np.cumsum(counts) - counts, counts)
            nxt = ch.next_idx[ch.next_ptr[c][rep] + offset]
            barred = turned[rep] & is_u[nxt]
            if barred.any():  # a second U-turn in one move, unless it is the only way on
                other = np.bincount(rep, weights=~barred, minlength=len(c)) > 0
                keep = ~barred | ~other[rep]
                rep, nxt = rep[keep], nxt[keep]
                counts = np.bincount(rep, minlength=len(c))
            if ch.weight is None:
                w = w[rep] / counts[rep] if split else w[rep]
            elif split:  # shares by weight
                share = ch.weight[nxt]
                w = w[rep] * share / np.bincount(rep, weights=share, minlength=len(c))[rep]
            else:  # every way keeps the whole times its weight against the likeliest way on (a dead end's U-turn: 1)
                way = ch.weight if ch.way is None else ch.way
                top = np.zeros(len(c))
                np.maximum.at(top, rep, way[nxt])
                w = w[rep] * ch.weight[nxt] / top[rep]
            src, q, c, turned = src[rep], q[rep], nxt, turned[rep] | is_u[nxt]
        if not out:
            empty = np.zeros(0, np.int64)
            return Moves(empty, empty, np.zeros(0))
        return Moves(*(np.concatenate(parts) for parts in zip(*out)))

    def _land(self, src: NDArray, c: NDArray, q: NDArray, w: NDArray) -> list[tuple[NDArray, NDArray, NDArray]]:
        """Split each landing position between the two nearest cell centres of its chain."""
        n = self.base[c + 1] - self.base[c]
        x = q / self.cell_len[c] - 0.5
        lo = np.clip(np.floor(x), 0, n - 1).astype(np.int64)
        frac = np.clip(x - lo, 0.0, 1.0)
        hi = np.minimum(lo + 1, n - 1)
        frac = np.where(hi == lo, 0.0, frac)
        parts = []
        for cell, share in ((lo, 1.0 - frac), (hi, frac)):
            keep = share > 0
            parts.append((src[keep], self.base[c[keep]] + cell[keep], w[keep] * share[keep]))
        return parts
