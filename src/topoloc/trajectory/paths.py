"""Training paths: simple paths with exactly ``path_nodes`` map nodes, by depth-limited DFS.

A *path* is a walk on the road multigraph whose vertices (and hence edges) are
distinct; parallel roads between the same two intersections give distinct
paths. From each source node the DFS enumerates every simple path with
exactly ``path_nodes`` nodes, following the direction of travel allowed by
``oneway`` when asked to. The paper's "modified depth-first search" between
chosen sources and targets is the same set: every target is the end of such
a path.

For big maps the enumeration explodes, so it can be capped per source and in
total. Sampling is deterministic for a seed: the sources are visited in a
seeded random order and each source explores its neighbours in a seeded
random order (so a capped source yields a spread of directions, not the first
branch only).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from topoloc.graph.road_graph import RoadGraph


@dataclass(frozen=True)
class Path:
    """Nodes ``n_0..n_k`` and the edges ``e_i`` between ``n_i`` and ``n_{i+1}``."""

    nodes: tuple[int, ...]
    edges: tuple[int, ...]


def adjacency(graph: RoadGraph, respect_oneway: bool = True) -> dict[int, list[tuple[int, int]]]:
    """Per node, the ``(edge_id, next_node)`` moves allowed, sorted by edge id (loops dropped)."""
    moves: dict[int, list[tuple[int, int]]] = {int(n): [] for n in graph.nodes.index}
    for edge_id, (u, v, oneway) in enumerate(zip(graph.edges.u, graph.edges.v, graph.edges.oneway)):
        u, v = int(u), int(v)
        if u == v:
            continue  # a loop can never be part of a simple path
        if not respect_oneway or oneway >= 0:
            moves[u].append((edge_id, v))
        if not respect_oneway or oneway <= 0:
            moves[v].append((edge_id, u))
    for node in moves:
        moves[node].sort()
    return moves


def paths_from(
    moves: dict[int, list[tuple[int, int]]],
    source: int,
    path_nodes: int,
    rng: np.random.Generator | None = None,
) -> Iterator[Path]:
    """Every simple path of exactly ``path_nodes`` nodes that starts at ``source`` (iterative DFS).

    With ``rng`` the neighbours of each node are tried in a random order,
    otherwise by edge id.
    """
    if path_nodes < 2:
        raise ValueError(f"path_nodes must be at least 2, got {path_nodes}")

    def options(node: int) -> list[tuple[int, int]]:
        opts = moves[node]
        if rng is None or len(opts) < 2:
            return opts
        return [opts[i] for i in rng.permutation(len(opts))]

    nodes = [source]
    edges: list[int] = []
    on_path = {source}
    stack = [iter(options(source))]
    while stack:
        step = next(stack[-1], None)
        if step is None:
            stack.pop()
            if edges:  # leave the node whose options are exhausted (never the source)
                edges.pop()
                on_path.discard(nodes.pop())
            continue
        edge_id, nxt = step
        if nxt in on_path:
            continue
        if len(nodes) + 1 == path_nodes:
            yield Path((*nodes, nxt), (*edges, edge_id))
            continue
        nodes.append(nxt)
        edges.append(edge_id)
        on_path.add(nxt)
        stack.append(iter(options(nxt)))


def sample_paths(
    graph: RoadGraph,
    path_nodes: int,
    *,
    respect_oneway: bool = True,
    sources: list[int] | None = None,
    max_per_source: int | None = None,
    max_total: int | None = None,
    seed: int = 0,
    shuffle: bool = True,
) -> Iterator[Path]:
    """Paths from each source (default: every node), capped per source and in total.

    Without caps and with ``shuffle=False`` this is the full enumeration in a
    fixed order (sources by node id, neighbours by edge id).
    """
    moves = adjacency(graph, respect_oneway)
    order = sorted(moves) if sources is None else [int(s) for s in sources]
    rng = np.random.default_rng(seed)
    if shuffle:
        order = [order[i] for i in rng.permutation(len(order))]
    total = 0
    for source in order:
        per_source = 0
        source_rng = np.random.default_rng([seed, source]) if shuffle else None
        for path in paths_from(moves, source, path_nodes, source_rng):
            yield path
            total += 1
            per_source += 1
            if max_total is not None and total >= max_total:
                return
            if max_per_source is not None and per_source >= max_per_source:
                break
