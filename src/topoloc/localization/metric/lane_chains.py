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


def lane_chains(graph: RoadGraph, states: DirectedEdges, turn_zone_m: float, heading_window_m: float,
                u_turn_weight: float = 1.0) -> Chains:
    """Middles and turn chains of ``graph`` (see the module docstring); a U-turn chain is entered with
    ``u_turn_weight`` times the share of any other turn (each of its two sweeps half of that)."""
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
    return Chains(
        length=np.concatenate([middle_len[middles], zone[src] + zone[dst]]),
        next_ptr=np.concatenate([[0], np.cumsum(counts)]),
        next_idx=np.array([c for s in successors for c in s], np.int64),
        first_state=np.concatenate([middles, src]),
        first_from=np.concatenate([zone[middles], length[src] - zone[src]]),
        split=np.concatenate([middle_len[middles], zone[src]]),
        second_state=np.concatenate([np.full(len(middles), -1), dst]),
        turn=np.concatenate([np.zeros(len(middles)), turn]),
        weight=np.concatenate([np.ones(len(middles)), np.where(u_turn, 0.5 * float(u_turn_weight), 1.0)]),
        way=np.concatenate([np.ones(len(middles)), np.where(u_turn, float(u_turn_weight), 1.0)]),
    )
