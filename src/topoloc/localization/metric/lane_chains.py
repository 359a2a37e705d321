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
8 m zones). With ``"node"`` it is the map's path; U-turns keep it either way.
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
                u_turn_weight: float = 1.0, turn_path: str = "node") -> Chains:
    """Middles and turn chains of ``graph`` (see the module docstring); a U-turn chain is entered with
    ``u_turn_weight`` times the share of any other turn (each of its two sweeps half of that); ``turn_path``
    (``arc`` or ``node``) sets how long a turn chain is driven."""
    if turn_path not in TURN_PATHS:
        raise ValueError(f"turn_path must be one of {TURN_PATHS}, got {turn_path!r}")
    valid = np.flatnonzero(states.valid)
    length = states.length
    zone = np.where(states.valid, np.minimum(float(turn_zone_m), length / 2.0), 0.0)
    middle_len = length - 2.0 * zone
    has_middle = states.valid & (middle_len > 1e-6)
    middles = np.flatnonzero(has_middle)
    middle_of = np.full(states.num_states, -1)
    middle_of[middles] = np.arange(len(middles))
    pairs = [(int(a), int(b)) for a in valid for b in states.next_states(int(a))]
    # a U-turn (back onto the same road) may sweep either way: left in right-hand traffic, right in left-hand
    # traffic or round a turning circle; its heading change of 180 deg alone cannot say which
    other_sweep = [(a, b) for a, b in pairs if b == a ^ 1]
    pairs += other_sweep
    src = np.array([a for a, _ in pairs], np.int64)
    dst = np.array([b for _, b in pairs], np.int64)
    turn_of: dict[int, list[int]] = {}  # directed edge -> its turn chains (by the edge they leave)
    first_turn = len(middles)
    for k, a in enumerate(src):
        turn_of.setdefault(int(a), []).append(first_turn + k)
    h_start, h_end = end_headings(graph, states, heading_window_m / 2.0)
    turn = np.angle(np.exp(1j * (h_start[dst] - h_end[src])))
    u_turn = dst == (src ^ 1)
    clockwise = np.arange(len(src)) >= len(src) - len(other_sweep)  # the copies appended above
    turn = np.where(u_turn, np.where(clockwise, -np.pi, np.pi), turn)

    successors: list[list[int]] = [turn_of.get(int(s), []) for s in middles]
    for b in dst:
        successors.append([int(middle_of[b])] if has_middle[b] else turn_of.get(int(b), []))
    counts = np.array([len(s) for s in successors], np.int64)
    on_map = zone[src] + zone[dst]
    driven = turn_arc_length(zone[src], zone[dst], turn) if turn_path == "arc" else on_map
    driven = np.where(u_turn | (driven <= 1e-6), on_map, driven)
    return Chains(
        length=np.concatenate([middle_len[middles], driven]),
        next_ptr=np.concatenate([[0], np.cumsum(counts)]),
        next_idx=np.array([c for s in successors for c in s], np.int64),
        first_state=np.concatenate([middles, src]),
        first_from=np.concatenate([zone[middles], length[src] - zone[src]]),
        split=np.concatenate([middle_len[middles], zone[src]]),
        second_state=np.concatenate([np.full(len(middles), -1), dst]),
        turn=np.concatenate([np.zeros(len(middles)), turn]),
        weight=np.concatenate([np.ones(len(middles)), np.where(u_turn, 0.5 * float(u_turn_weight), 1.0)]),
        way=np.concatenate([np.ones(len(middles)), np.where(u_turn, float(u_turn_weight), 1.0)]),
        stretch=np.concatenate([np.ones(len(middles)), on_map / np.maximum(driven, 1e-9)]) if turn_path == "arc" else None,
    )
