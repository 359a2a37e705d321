"""Routes as chains of road edges: planning the shortest drivable one, checking one, and finding each edge's entry node.

A route is a list of road edges, each entered from a node; it is drivable when the edges chain up end to end and
none is driven against its one-way restriction (:func:`check_route`).
"""

from __future__ import annotations

import itertools

import networkx as nx
import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph


def check_route(graph: RoadGraph, edges: list[int], froms: list[int], where: str = "route") -> None:
    """InputError naming ``where`` unless the edges chain up end to end and none is driven against its one-way."""
    if not edges or len(edges) != len(froms):
        raise InputError(where, "a route needs at least one edge and one entry node per edge")
    for i, (e, f) in enumerate(zip(edges, froms)):
        if not 0 <= int(e) < graph.num_edges:
            raise InputError(where, f"edge {e} is not in the road graph ({graph.num_edges} edges)")
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        if f not in (u, v):
            raise InputError(where, f"edge {e} does not start at node {f}")
        ow = int(graph.edges.oneway.iat[e])
        if ow == 1 and f != u or ow == -1 and f != v:
            raise InputError(where, f"edge {e} ({graph.edges['name'].iat[e] or graph.edges.highway.iat[e]}) is one-way "
                             f"against the route: it cannot be driven from node {f}")
        if i and graph.other_end(edges[i - 1], froms[i - 1]) != f:
            raise InputError(where, f"edge {e} does not continue edge {edges[i - 1]}: the route is not connected")


def plan_route(graph: RoadGraph, start: int, goal: int) -> tuple[list[int], list[int]]:
    """The shortest drivable chain of edges from node ``start`` to node ``goal`` (one-way roads respected).

    InputError when either node is not in the graph or the goal cannot be reached (a disconnected goal, or
    one reachable only against one-way roads).
    """
    for name, node in (("start", start), ("goal", goal)):
        if node not in graph.nodes.index:
            raise InputError(f"route.{name}", f"node {node} is not in the road graph")
    directed = nx.DiGraph()
    for e in range(graph.num_edges):
        u, v, ow, length = (int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e]), int(graph.edges.oneway.iat[e]),
                            float(graph.edges.length_m.iat[e]))
        for a, b, ok in ((u, v, ow >= 0), (v, u, ow <= 0)):
            if ok and (not directed.has_edge(a, b) or directed[a][b]["length"] > length):
                directed.add_edge(a, b, length=length, edge=e)
    try:
        nodes = nx.shortest_path(directed, start, goal, weight="length")
    except (nx.NetworkXNoPath, nx.NodeNotFound) as err:
        raise InputError("route", f"no drivable route from node {start} to node {goal} (one-way roads or a "
                         "disconnected goal)") from err
    if len(nodes) < 2:
        raise InputError("route", "start and goal are the same node")
    return [int(directed[a][b]["edge"]) for a, b in itertools.pairwise(nodes)], [int(a) for a in nodes[:-1]]


def route_froms(graph: RoadGraph, edges: list[int], start_xy: NDArray[np.float64]) -> list[int]:
    """The entry node of each edge of a connected chain (the first: the end nearer to ``start_xy``)."""
    froms: list[int] = []
    for i, e in enumerate(edges):
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        if i == 0:
            nxt = {int(graph.edges.u.iat[edges[1]]), int(graph.edges.v.iat[edges[1]])} if len(edges) > 1 else set()
            shared = {u, v} & nxt
            froms.append(_nearer(graph, (u, v), start_xy) if len(shared) != 1 or u == v else (v if u in shared else u))
        else:
            froms.append(graph.other_end(edges[i - 1], froms[-1]))
    return froms


def _nearer(graph: RoadGraph, nodes: tuple[int, int], xy: NDArray[np.float64]) -> int:
    pos = graph.nodes.loc[list(nodes), ["x", "y"]].to_numpy(float)
    return int(nodes[int(np.argmin(np.hypot(*(pos - np.asarray(xy, float)).T)))])
