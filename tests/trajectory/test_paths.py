"""DFS training paths against networkx on tiny graphs."""

from __future__ import annotations

import networkx as nx
import pytest

from topoloc.trajectory.paths import sample_paths
from trajectory_helpers import make_graph, random_graph


def nx_paths(graph, path_nodes: int, respect_oneway: bool) -> set[tuple[tuple[int, ...], tuple[int, ...]]]:
    """(nodes, edges) of every simple path of exactly ``path_nodes`` nodes, by networkx."""
    g = nx.MultiDiGraph()
    g.add_nodes_from(graph.nodes.index)
    for edge_id, (u, v, oneway) in enumerate(zip(graph.edges.u, graph.edges.v, graph.edges.oneway)):
        if not respect_oneway or oneway >= 0:
            g.add_edge(u, v, key=edge_id)
        if not respect_oneway or oneway <= 0:
            g.add_edge(v, u, key=edge_id)
    found = set()
    for s in g.nodes:
        for t in g.nodes:
            if s == t:
                continue
            for edge_path in nx.all_simple_edge_paths(g, s, t, cutoff=path_nodes - 1):
                if len(edge_path) == path_nodes - 1:
                    nodes = (edge_path[0][0], *(e[1] for e in edge_path))
                    found.add((tuple(int(n) for n in nodes), tuple(int(e[2]) for e in edge_path)))
    return found


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("path_nodes", [2, 3, 5])
def test_dfs_equals_networkx(seed, path_nodes):
    graph = random_graph(seed, n=9, extra=5)
    ours = [(p.nodes, p.edges) for p in sample_paths(graph, path_nodes, respect_oneway=False, shuffle=False)]
    assert len(ours) == len(set(ours)), "a path was produced twice"
    assert set(ours) == nx_paths(graph, path_nodes, respect_oneway=False)
    for nodes, edges in ours:
        assert len(nodes) == path_nodes == len(set(nodes))
        assert len(edges) == path_nodes - 1 == len(set(edges))


def test_parallel_edges_are_distinct_paths_and_oneway_respected():
    coords = {1: (0, 0), 2: (100, 0), 3: (200, 0), 4: (100, 80)}
    # edges 0 and 1 are parallel roads 1-2; edge 2 is one-way 2->3; edge 3 one-way 4->2 (stored as 2,4 with -1).
    graph = make_graph(coords, [(1, 2), (1, 2), (2, 3, 1), (2, 4, -1)])
    ours = {(p.nodes, p.edges) for p in sample_paths(graph, 3, respect_oneway=True, shuffle=False)}
    assert ours == nx_paths(graph, 3, respect_oneway=True)
    assert ((1, 2, 3), (0, 2)) in ours and ((1, 2, 3), (1, 2)) in ours
    assert not any(nodes[:2] == (3, 2) for nodes, _ in ours)  # 3->2 is against the one-way
    assert ((4, 2, 1), (3, 0)) in ours and not any(nodes[-1] == 4 for nodes, _ in ours)
    both = {(p.nodes, p.edges) for p in sample_paths(graph, 3, respect_oneway=False, shuffle=False)}
    assert both == nx_paths(graph, 3, respect_oneway=False) and len(both) > len(ours)


def test_caps_are_deterministic_and_bounded():
    graph = random_graph(3, n=12, extra=8)
    full = {(p.nodes, p.edges) for p in sample_paths(graph, 5, respect_oneway=False)}
    capped = [(p.nodes, p.edges) for p in sample_paths(graph, 5, respect_oneway=False, max_per_source=3, seed=7)]
    again = [(p.nodes, p.edges) for p in sample_paths(graph, 5, respect_oneway=False, max_per_source=3, seed=7)]
    other = [(p.nodes, p.edges) for p in sample_paths(graph, 5, respect_oneway=False, max_per_source=3, seed=8)]
    assert capped == again and capped != other
    assert set(capped) <= full
    per_source = {}
    for nodes, _ in capped:
        per_source[nodes[0]] = per_source.get(nodes[0], 0) + 1
    assert max(per_source.values()) == 3
    total = list(sample_paths(graph, 5, respect_oneway=False, max_total=10, seed=7))
    assert len(total) == 10
