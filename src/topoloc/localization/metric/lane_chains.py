"""Chains for the metric filter: road middles and turns through the intersections.

A vehicle starts to turn before an intersection and finishes after it, so
its heading near a node depends on where it comes from and where it goes.
Every directed edge is cut into a *turn zone* at each end (``turn_zone_m``,
at most half the road) and its *middle*; every allowed move from directed
edge ``a`` into ``b`` (:mod:`topoloc.localization.connectivity`) becomes a
*turn chain* from the start of ``a``'s end zone, through the node, to the
end of ``b``'s start zone. A vehicle in a middle chooses its next turn when
it enters the end zone (equal shares), then drives the turn chain, then the
middle of ``b`` (or, when ``b`` is shorter than two zones, its next turn).
On a turn chain the map heading sweeps smoothly from ``a``'s to ``b``'s
(:class:`topoloc.localization.metric.cell_grid.CellGrid`), as a vehicle's heading does.

With ``turn_path="arc"`` a turn chain is as long as a car drives it: the circular arc
tangent to both roads where the shorter of the two zones ends (:func:`turn_arc_length`),
shorter than the map's path through the node (by 3.4 m for a right angle between
8 m zones), and its heading turns evenly along the arc. With ``"node"`` it is the
map's path; U-turns keep it either way.

With ``u_turn_gap_m`` a U-turn may also be driven across a median that wide, as
a car turns through the opening of a dual carriageway that the map has as one
two-way road (``u_turn_gap_m`` from lane to lane): a second U-turn chain, a
quarter turn over each turn zone, straight at right angles across the rest of
the gap between them; its cells spread over the map's path through the node.

With ``wide_zone_m`` over ``turn_zone_m`` a vehicle may also turn widely: every turn
but a U-turn has a second chain through zones of ``wide_zone_m``; a road's middle
ends that far before its node, where ``wide_share`` of the vehicles (by default half)
take a wide turn and the others drive on (an *approach*) to the turn zone, and after a
turn drive out of it (an *exit*) to the next middle.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.connectivity import DirectedEdges
from topoloc.localization.metric.cell_grid import Chains, polyline_headings, state_coords


def end_headings(graph: RoadGraph, states: DirectedEdges, half: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Heading (radians) of every valid directed edge where it starts and where it ends, over ``half`` metres."""
    start = np.zeros(states.num_states)
    end = np.zeros(states.num_states)
    for s in np.flatnonzero(states.valid):
        coords = state_coords(graph, int(s))
        length = states.length[s]
        start[s], end[s] = np.radians(polyline_headings(coords, np.array([0.0, length]), half))
    return start, end


#: Turns sharper than this are cut as this much: a fillet tangent at the zones' ends would be tighter than a car turns.
MAX_ARC_TURN_DEG = 120.0
TURN_PATHS = ("arc", "node")
#: Turns below this have no wide way (``wide_zone_m``): a road that goes on nearly straight is driven alike either way.
MIN_WIDE_TURN_DEG = 30.0


def turn_arc_length(zone_in: NDArray[np.float64], zone_out: NDArray[np.float64],
                    turn: NDArray[np.float64]) -> NDArray[np.float64]:
    """Metres a car drives from ``zone_in`` before a node to ``zone_out`` after it when the roads meet at ``turn``
    radians: straight up to the shorter zone's length from the node, then the arc tangent to both roads there
    (radius ``z / tan(turn / 2)``, turns over :data:`MAX_ARC_TURN_DEG` cut as that much)."""
    z = np.minimum(zone_in, zone_out)
    angle = np.minimum(np.abs(turn), np.radians(MAX_ARC_TURN_DEG))
    half = np.maximum(np.tan(angle / 2.0), 1e-12)
    ratio = np.where(angle > 1e-9, angle / (2.0 * half), 1.0)  # arc length over the two tangents' 2 z
    return zone_in + zone_out - 2.0 * z * (1.0 - ratio)


def lane_chains(graph: RoadGraph, states: DirectedEdges, turn_zone_m: float, heading_window_m: float,
                u_turn_weight: float = 1.0, turn_path: str = "node", wide_zone_m: float = 0.0,
                u_turn_gap_m: float = 0.0, wide_share: float = 0.5,
                entry_weight: NDArray[np.float64] | None = None) -> Chains:
    """Middles and turn chains of ``graph`` (see the module docstring); a U-turn chain is entered with
    ``u_turn_weight`` times the share of any other turn (each of its two sweeps half of that); ``turn_path``
    (``arc`` or ``node``) sets how long a turn chain is driven. With ``wide_zone_m`` over ``turn_zone_m`` every turn
    but a U-turn may also be driven widely, through zones of ``wide_zone_m`` (at most half the road): a middle then
    ends that far before the node, where ``wide_share`` of the vehicles (by default half) take a wide turn and the
    others drive on to the turn zone (an *approach*), take a turn there and drive out of it (an *exit*) to the next
    middle. With ``u_turn_gap_m`` over 0 a U-turn may also cross a median that wide (module docstring), sharing the
    U-turn's weight with the tight one. ``entry_weight`` (per state, at most 1) weighs a turn onto a state of lower
    weight by the ratio (roads added to the map: :mod:`~topoloc.localization.metric.merged_duals`)."""
    if turn_path not in TURN_PATHS:
        raise ValueError(f"turn_path must be one of {TURN_PATHS}, got {turn_path!r}")
    if not 0.0 < wide_share < 1.0:
        raise ValueError(f"wide_share must lie strictly between 0 and 1, got {wide_share}")
    valid = np.flatnonzero(states.valid)
    length = states.length
    zone = np.where(states.valid, np.minimum(float(turn_zone_m), length / 2.0), 0.0)
    wide = np.where(states.valid, np.minimum(max(float(wide_zone_m), float(turn_zone_m)), length / 2.0), 0.0)
    core_len = length - 2.0 * wide
    has_core = states.valid & (core_len > 1e-6)
    has_edge = states.valid & (wide - zone > 1e-6)  # an exit after the start zone, an approach before the end one
    cores, edged = np.flatnonzero(has_core), np.flatnonzero(has_edge)
    pairs = [(int(a), int(b)) for a in valid for b in states.next_states(int(a))]
    # a U-turn (back onto the same road) may sweep either way: left in right-hand traffic, right in left-hand
    # traffic or round a turning circle; its heading change of 180 deg alone cannot say which
    u_at = [k for k, (a, b) in enumerate(pairs) if b == a ^ 1]
    u_pairs = [pairs[k] for k in u_at]
    n_plain = len(pairs)
    sweeps = [False] * n_plain + [True] * len(u_pairs)  # clockwise: the second sweep, a copy
    pairs += u_pairs
    n_tight = len(pairs)
    gap = max(float(u_turn_gap_m), 0.0)
    if gap > 0:  # both sweeps again, across the median
        pairs += u_pairs + u_pairs
        sweeps += [False] * len(u_pairs) + [True] * len(u_pairs)
    across = np.arange(len(pairs)) >= n_tight  # the U-turns across a median
    src = np.array([a for a, _ in pairs], np.int64)
    dst = np.array([b for _, b in pairs], np.int64)
    h_start, h_end = end_headings(graph, states, heading_window_m / 2.0)
    turn = np.angle(np.exp(1j * (h_start[dst] - h_end[src])))
    u_turn = dst == (src ^ 1)
    turn = np.where(u_turn, np.where(np.array(sweeps, bool), -np.pi, np.pi), turn)
    # a wide way through the node for every turn but a U-turn; a road that goes on within 30 deg is driven alike
    widens = np.flatnonzero(~u_turn & (np.abs(turn) >= np.radians(MIN_WIDE_TURN_DEG))
                            & ((wide[src] - zone[src]) + (wide[dst] - zone[dst]) > 1e-6))

    # chain ids: exits, cores (the middles), approaches, turns, wide turns
    n_edge, n_core, n_turn = len(edged), len(cores), len(src)
    exit_of, core_of, approach_of = (np.full(states.num_states, -1) for _ in range(3))
    exit_of[edged] = np.arange(n_edge)
    core_of[cores] = n_edge + np.arange(n_core)
    approach_of[edged] = n_edge + n_core + np.arange(n_edge)
    first_turn, first_wide = n_edge + n_core + n_edge, n_edge + n_core + n_edge + n_turn
    turns_of: dict[int, list[int]] = {}
    for k, a in enumerate(src):
        turns_of.setdefault(int(a), []).append(first_turn + k)
    wides_of: dict[int, list[int]] = {}
    for k, i in enumerate(widens):
        wides_of.setdefault(int(src[i]), []).append(first_wide + k)

    def branch(s: int) -> list[int]:  # where the middle of s ends: on to the turn zone, or a wide turn
        return ([int(approach_of[s])] if has_edge[s] else turns_of.get(s, [])) + wides_of.get(s, [])

    def after_exit(s: int) -> list[int]:  # wide_zone_m into s
        return [int(core_of[s])] if has_core[s] else branch(s)

    successors: list[list[int]] = [after_exit(int(s)) for s in edged] + [branch(int(s)) for s in cores]
    successors += [turns_of.get(int(s), []) for s in edged]
    successors += [[int(exit_of[b])] if has_edge[b] else after_exit(int(b)) for b in dst]
    successors += [after_exit(int(dst[i])) for i in widens]
    counts = np.array([len(s) for s in successors], np.int64)

    on_map = np.concatenate([zone[src] + zone[dst], wide[src[widens]] + wide[dst[widens]]])
    both_turn = np.concatenate([turn, turn[widens]])
    both_u = np.concatenate([u_turn, np.zeros(len(widens), bool)])
    driven = on_map
    zin = np.concatenate([zone[src], wide[src[widens]]])
    zout = np.concatenate([zone[dst], wide[dst[widens]]])
    if turn_path == "arc":
        driven = turn_arc_length(zin, zout, both_turn)
    curved = ~both_u & (driven > 1e-6) if turn_path == "arc" else np.zeros(len(driven), bool)
    both_across = np.concatenate([across, np.zeros(len(widens), bool)])
    # a U-turn across: a quarter turn over each zone (radius 2 z / pi), straight between them over the rest of the gap
    plateau = np.where(both_across, np.maximum(gap - 2.0 / np.pi * on_map, 0.0), 0.0)
    driven = np.where(curved, driven, on_map) + plateau
    arc_from = np.where(curved, zin - np.minimum(zin, zout), 0.0)  # straight up to the shorter zone's length
    arc_len = np.where(curved, driven - (zin + zout - 2.0 * np.minimum(zin, zout)), 0.0)
    arc_len = np.where(both_across, on_map, arc_len)
    turn_weight = np.where(u_turn, (0.25 if gap > 0 else 0.5) * float(u_turn_weight), 1.0)
    turn_way = np.where(u_turn, float(u_turn_weight), 1.0)
    wide_weight = np.ones(len(widens))
    if entry_weight is not None:  # onto a road of lower weight: that much less likely
        entry = np.minimum(1.0, entry_weight[dst] / entry_weight[src])
        turn_weight, turn_way, wide_weight = turn_weight * entry, turn_way * entry, entry[widens]
    wides_weight = np.array([wide_weight[np.asarray(wides_of.get(int(s), []), np.int64) - first_wide].sum()
                             for s in edged], float)
    # the approach's weight: wide_share of the vehicles at a middle's end take one of its wide turns (by their weights)
    approach = np.where(wides_weight > 0, wides_weight * (1.0 - float(wide_share)) / float(wide_share), 1.0)
    ones = np.ones(n_edge + n_core)
    shaped = turn_path == "arc" or gap > 0  # some turn chains are not the map's path through the node
    plain_turn = None
    if gap > 0 or n_edge > 0:  # each way among the plain turns: a turn its own, a U-turn across its tight one, a wide
        # turn the tight turn of the same pair; pieces of one road (exits, middles, approaches) none
        tight = np.concatenate([np.asarray(u_at, np.int64), n_plain + np.arange(len(u_pairs))])
        plain_turn = np.concatenate([np.full(n_edge + n_core + n_edge, -1), np.arange(n_tight),
                                     tight[:len(src) - n_tight], widens]).astype(np.int64)
    return Chains(
        length=np.concatenate([wide[edged] - zone[edged], core_len[cores], wide[edged] - zone[edged], driven]),
        next_ptr=np.concatenate([[0], np.cumsum(counts)]),
        next_idx=np.array([c for s in successors for c in s], np.int64),
        first_state=np.concatenate([edged, cores, edged, src, src[widens]]),
        first_from=np.concatenate([zone[edged], wide[cores], length[edged] - wide[edged], length[src] - zone[src],
                                   length[src[widens]] - wide[src[widens]]]),
        split=np.concatenate([wide[edged] - zone[edged], core_len[cores], wide[edged] - zone[edged], zone[src],
                              wide[src[widens]]]),
        second_state=np.concatenate([np.full(n_edge + n_core + n_edge, -1), dst, dst[widens]]),
        turn=np.concatenate([np.zeros(n_edge + n_core + n_edge), turn, turn[widens]]),
        weight=np.concatenate([ones, approach, turn_weight, wide_weight]),
        way=np.concatenate([ones, approach, turn_way, wide_weight]),
        stretch=np.concatenate([np.ones(n_edge + n_core + n_edge), on_map / np.maximum(driven, 1e-9)])
        if shaped else None,
        arc_from=np.concatenate([np.zeros(n_edge + n_core + n_edge), arc_from]) if shaped else None,
        arc_len=np.concatenate([np.zeros(n_edge + n_core + n_edge), arc_len]) if shaped else None,
        plateau=np.concatenate([np.zeros(n_edge + n_core + n_edge), plateau]) if gap > 0 else None,
        plain_turn=plain_turn,
    )
