"""Directed-edge states of a road graph and which state can follow which.

The RNN's classes are undirected edge ids, but a vehicle on a road travels in
one direction, and where it can go next depends on it. A *state* is an edge
travelled in one direction: state ``2 e`` is edge ``e`` from ``u`` to ``v``,
state ``2 e + 1`` from ``v`` to ``u``; one-way roads have one valid state.

Between two tokens a vehicle either stays on its road (a road with virtual
nodes yields several tokens) or passes the node at the end of its state onto
a road leaving that node, in a direction its one-way tag allows. A step is at
most about one virtual-node spacing long, so it can also cross roads shorter
than ``max_skip_m`` without a token on them: those are successors too.
U-turns (onto the reverse of the same road) are allowed ``never``, only at
``dead_ends`` (default), or ``always``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph

U_TURNS = ("never", "dead_ends", "always")


@dataclass(frozen=True)
class DirectedEdges:
    """States (directed edges) of a road graph and their moves.

    Attributes
    ----------
    edge
        ``(S,)`` undirected edge id of each state (``S = 2 E``).
    valid
        ``(S,)`` whether the state's direction is allowed (one-way roads have one valid state).
    start, end
        ``(S,)`` node ids where the state starts and ends.
    length
        ``(S,)`` road length in metres.
    next_ptr, next_idx
        CSR lists of the states that can follow a state across the node at its end (one hop).
    successors
        ``(S, M)`` states reachable in one token step, ``-1`` padded; column 0 is the state itself.
    """

    edge: NDArray[np.int64]
    valid: NDArray[np.bool_]
    start: NDArray[np.int64]
    end: NDArray[np.int64]
    length: NDArray[np.float64]
    next_ptr: NDArray[np.int64]
    next_idx: NDArray[np.int64]
    successors: NDArray[np.int64]

    @property
    def num_states(self) -> int:
        return len(self.edge)

    @property
    def num_edges(self) -> int:
        return len(self.edge) // 2

    def next_states(self, state: int) -> NDArray[np.int64]:
        """States that can follow ``state`` across its end node."""
        return self.next_idx[self.next_ptr[state]:self.next_ptr[state + 1]]

    def states_of(self, edges: NDArray[np.int64]) -> NDArray[np.int64]:
        """The valid states of undirected ``edges`` (one or two each)."""
        both = np.stack([2 * np.asarray(edges, np.int64), 2 * np.asarray(edges, np.int64) + 1], axis=-1).reshape(-1)
        return both[self.valid[both]]


def _one_hop(start: NDArray, end: NDArray, valid: NDArray, u_turns: str) -> list[list[int]]:
    leaving: dict[int, list[int]] = {}
    for s in np.flatnonzero(valid):
        leaving.setdefault(int(start[s]), []).append(int(s))
    moves = []
    for s in range(len(start)):
        if not valid[s]:
            moves.append([])
            continue
        out = leaving.get(int(end[s]), [])
        ahead = [t for t in out if t != s ^ 1]
        if u_turns == "always" or (u_turns == "dead_ends" and not ahead):
            ahead = out
        moves.append(sorted(ahead))
    return moves


def directed_edges(graph: RoadGraph, u_turns: str = "dead_ends", max_skip_m: float | None = None) -> DirectedEdges:
    """The states of ``graph`` and their moves; ``max_skip_m`` defaults to the virtual-node spacing."""
    if u_turns not in U_TURNS:
        raise InputError("localization.decode.u_turns", f"must be one of {list(U_TURNS)}, got {u_turns!r}")
    edges = graph.edges
    n = len(edges)
    u, v = edges.u.to_numpy(np.int64), edges.v.to_numpy(np.int64)
    oneway = edges.oneway.to_numpy(np.int64)
    start = np.stack([u, v], axis=1).reshape(-1)
    end = np.stack([v, u], axis=1).reshape(-1)
    valid = np.stack([oneway >= 0, oneway <= 0], axis=1).reshape(-1)
    length = np.repeat(edges.length_m.to_numpy(float), 2)
    moves = _one_hop(start, end, valid, u_turns)
    skip = graph.virtual_node_spacing_m if max_skip_m is None else float(max_skip_m)
    successors: list[list[int]] = []
    for s in range(2 * n):
        if not valid[s]:
            successors.append([])
            continue
        found = [s]
        seen = {s}
        frontier = [(t, 0.0) for t in moves[s]]
        while frontier:  # breadth first through roads shorter than what one step can cross
            t, crossed = frontier.pop(0)
            if t in seen:
                continue
            seen.add(t)
            found.append(t)
            if crossed + length[t] < skip:
                frontier.extend((w, crossed + length[t]) for w in moves[t])
        successors.append(found)
    width = max(1, max(len(f) for f in successors))
    table = np.full((2 * n, width), -1, dtype=np.int64)
    for s, found in enumerate(successors):
        table[s, :len(found)] = found
    counts = np.array([len(m) for m in moves], dtype=np.int64)
    ptr = np.concatenate([[0], np.cumsum(counts)])
    idx = np.array([t for m in moves for t in m], dtype=np.int64)
    return DirectedEdges(np.arange(2 * n) // 2, valid, start, end, length, ptr, idx, table)


def connected_keys(states: DirectedEdges) -> NDArray[np.int64]:
    """Sorted keys ``a * E + b`` of undirected edge pairs ``(a, b)`` where ``b`` can follow ``a`` in one step."""
    n = states.num_edges
    src = np.repeat(states.edge, states.successors.shape[1])
    dst_state = states.successors.reshape(-1)
    keep = dst_state >= 0
    keys = src[keep] * n + states.edge[dst_state[keep]]
    return np.unique(np.concatenate([keys, np.arange(n) * n + np.arange(n)]))


def consecutive_connected(states: DirectedEdges, edges: NDArray[np.int64], keys: NDArray[np.int64] | None = None) -> NDArray[np.bool_]:
    """Per consecutive pair of an edge sequence: is the second reachable from the first in one step (either way)?"""
    edges = np.asarray(edges, np.int64)
    if len(edges) < 2:
        return np.zeros(0, dtype=bool)
    keys = connected_keys(states) if keys is None else keys
    n = states.num_edges
    a, b = edges[:-1], edges[1:]
    return np.isin(a * n + b, keys) | np.isin(b * n + a, keys)
