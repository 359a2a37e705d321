"""Edits of a road graph that the map errors of :mod:`topoloc.odometry.map_errors` are made of.

:func:`build_graph` (a :class:`RoadGraph` from nodes, edge records and geometry), :func:`displace` (nodes moved,
roads bent), :func:`curvy` (straight roads given an S-bend), :func:`simplify` (Douglas-Peucker),
:func:`straight_chains` and :func:`split_dual` (straight chains of two-way roads made dual carriageways),
:func:`add_detours` (service-road loops), :func:`drop_roads` (roads removed, the graph kept connected) and
:func:`inner_turn` (how much a road turns within itself), :func:`crop_graph` (the roads near the middle).
"""

from __future__ import annotations

from typing import Any

import networkx as nx
import numpy as np
import pandas as pd
from numpy.typing import NDArray

from topoloc.geometry import virtual_node_count
from topoloc.graph.road_graph import EDGE_COLUMNS, RoadGraph
from topoloc.segmentation import douglas_peucker

def build_graph(nodes: pd.DataFrame, records: list[dict[str, Any]], geometry: list[NDArray[np.float64]],
                like: RoadGraph) -> RoadGraph:
    """A :class:`RoadGraph` of ``nodes`` (``x``, ``y``, indexed by node id) and edges (``records`` with at least
    ``u``, ``v``, ``oneway``; the rest of :data:`EDGE_COLUMNS` defaulted) with ``geometry`` from ``u`` to ``v``:
    lengths, virtual nodes and degrees computed, CRS and spacing of ``like``; nodes no edge uses dropped."""
    spacing = like.virtual_node_spacing_m
    rows = []
    for rec, coords in zip(records, geometry):
        length = float(np.hypot(*np.diff(coords, axis=0).T).sum())
        rows.append({"highway": "residential", "name": "", "osm_way_ids": "", "lanes": np.nan, "width_m": np.nan,
                     **rec, "length_m": length, "virtual_nodes": virtual_node_count(length, spacing)})
    edges = pd.DataFrame(rows, columns=EDGE_COLUMNS).reset_index(drop=True)
    edges.index.name = "edge_id"
    degree = pd.concat([edges.u, edges.v]).value_counts()
    nodes = nodes.loc[nodes.index.isin(degree.index)].copy()
    for col in ("lon", "lat"):
        if col not in nodes:
            nodes[col] = 0.0
    nodes = nodes[["x", "y", "lon", "lat"]].copy()
    nodes["degree"] = degree.reindex(nodes.index).astype(int)
    nodes.index.name = "node_id"
    return RoadGraph(nodes, edges, [np.asarray(g, float) for g in geometry], like.crs, spacing, dict(like.meta))


def records_of(graph: RoadGraph) -> list[dict[str, Any]]:
    """The edges of ``graph`` as plain records (one dict of its columns per edge, in edge-id order)."""
    return graph.edges.reset_index(drop=True).to_dict("records")


def copy_graph(graph: RoadGraph) -> RoadGraph:
    """A deep copy of ``graph`` (its nodes, edges and geometry), rebuilt so nothing is shared with it."""
    return build_graph(graph.nodes.copy(), records_of(graph), [g.copy() for g in graph.geometry], graph)


def normals(coords: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit normals to the right of a polyline at its points (averaged over the neighbouring segments)."""
    tangent = np.gradient(coords, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    return np.column_stack([tangent[:, 1], -tangent[:, 0]])


def _along(coords: NDArray[np.float64]) -> NDArray[np.float64]:
    """Share of the length along a polyline at each of its points (0 to 1)."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
    return cum / max(cum[-1], 1e-12)


def densify(coords: NDArray[np.float64], step_m: float = 5.0) -> NDArray[np.float64]:
    """The polyline ``coords`` ``(n, 2)`` with points added at most ``step_m`` apart along it (its own points kept)."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
    s = np.union1d(np.linspace(0.0, cum[-1], max(2, int(np.ceil(cum[-1] / step_m)) + 1)), cum)
    return np.column_stack([np.interp(s, cum, coords[:, 0]), np.interp(s, cum, coords[:, 1])])


def _bend(coords: NDArray[np.float64], amplitude: float, waves: float = 0.5) -> NDArray[np.float64]:
    """``coords`` densified and bent sideways by ``amplitude * sin(2 pi waves s)``, the ends kept."""
    dense = densify(coords)
    s = _along(dense)
    return dense + (amplitude * np.sin(2.0 * np.pi * waves * s))[:, None] * normals(dense)


def displace(graph: RoadGraph, node_m: float, curve_m: float, rng: np.random.Generator) -> RoadGraph:
    """Nodes moved by up to ``node_m``, the geometry following linearly, each road bent by up to ``curve_m``."""
    angle = rng.uniform(0.0, 2.0 * np.pi, len(graph.nodes))
    size = rng.uniform(0.0, node_m, len(graph.nodes))
    shift = pd.DataFrame({"dx": size * np.cos(angle), "dy": size * np.sin(angle)}, index=graph.nodes.index)
    nodes = graph.nodes.copy()
    nodes["x"] += shift.dx
    nodes["y"] += shift.dy
    geometry = []
    for e, coords in enumerate(graph.geometry):
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        bent = _bend(coords, rng.uniform(-curve_m, curve_m)) if curve_m > 0 else coords.copy()
        s = _along(bent)[:, None]
        du, dv = shift.loc[u].to_numpy(float), shift.loc[v].to_numpy(float)
        geometry.append(bent + (1.0 - s) * du + s * dv)
    return build_graph(nodes, records_of(graph), geometry, graph)


def curvy(graph: RoadGraph, low_m: float, high_m: float, rng: np.random.Generator, min_length_m: float = 40.0) -> RoadGraph:
    """Straight roads (two points, at least ``min_length_m``) given an S-bend of ``low_m``-``high_m``."""
    geometry = [(_bend(c, rng.uniform(low_m, high_m) * rng.choice([-1.0, 1.0]), waves=1.0)
                 if len(c) == 2 and np.hypot(*(c[-1] - c[0])) >= min_length_m else c.copy()) for c in graph.geometry]
    return build_graph(graph.nodes.copy(), records_of(graph), geometry, graph)


def simplify(graph: RoadGraph, tolerance_m: float) -> RoadGraph:
    """Every road's geometry simplified by Douglas-Peucker at ``tolerance_m`` (ends kept)."""
    geometry = [c[douglas_peucker(c, tolerance_m)] for c in graph.geometry]
    return build_graph(graph.nodes.copy(), records_of(graph), geometry, graph)


def inner_turn(coords: NDArray[np.float64]) -> float:
    """The largest heading change (radians) between the first segment of a polyline and any later one."""
    d = np.diff(coords, axis=0)
    d = d[np.hypot(*d.T) > 1e-9]
    if len(d) < 2:
        return 0.0
    angle = np.arctan2(d[:, 1], d[:, 0])
    return float(np.abs((angle - angle[0] + np.pi) % (2 * np.pi) - np.pi).max())


def straight_chains(graph: RoadGraph, max_turn_deg: float = 20.0, min_length_m: float = 150.0) -> list[list[tuple[int, int]]]:
    """Chains of straight two-way roads that continue straight through nodes (turns below ``max_turn_deg``, also
    within a road), as lists of
    (edge, node entered from), at least ``min_length_m`` long; each road in at most one chain."""
    used: set[int] = set()
    chains = []
    g = graph.graph

    def usable(e: int) -> bool:
        return (graph.edges.oneway.iat[e] == 0 and graph.edges.u.iat[e] != graph.edges.v.iat[e]
                and inner_turn(graph.geometry[e]) < np.radians(max_turn_deg))

    def heading(e: int, node: int, leaving: bool) -> float:
        c = graph.edge_coords(e, node) if leaving else graph.edge_coords(e, graph.other_end(e, node))
        d = c[1] - c[0] if leaving else c[-1] - c[-2]
        return float(np.arctan2(d[1], d[0]))

    def straightest(e: int, node: int) -> int | None:
        best, best_turn = None, np.radians(max_turn_deg)
        h = heading(e, node, leaving=False)
        for _, _, key in g.edges(node, keys=True):
            if key == e or key in used or not usable(key):
                continue
            turn = abs((heading(key, node, leaving=True) - h + np.pi) % (2 * np.pi) - np.pi)
            if turn < best_turn:
                best, best_turn = key, turn
        return best

    for e in range(graph.num_edges):
        if e in used or not usable(e):
            continue
        chain = [(e, int(graph.edges.u.iat[e]))]
        used.add(e)
        for forward in (True, False):
            while True:
                last, start = chain[-1] if forward else chain[0]
                end = graph.other_end(last, start)
                if forward:
                    nxt = straightest(last, end)
                    if nxt is None or graph.other_end(nxt, end) in {f for _, f in chain}:
                        break
                    chain.append((nxt, end))
                else:
                    nxt = straightest(last, start)
                    if nxt is None or graph.other_end(nxt, start) in {f for _, f in chain} | {end}:
                        break
                    chain.insert(0, (nxt, graph.other_end(nxt, start)))
                used.add(nxt)
        if float(graph.edges.length_m.iloc[[c for c, _ in chain]].sum()) >= min_length_m:
            chains.append(chain)
        else:
            used.difference_update(c for c, _ in chain[1:])
    return chains


def split_dual(graph: RoadGraph, chains: list[list[tuple[int, int]]], gap_m: NDArray[np.float64]
               ) -> tuple[RoadGraph, dict[int, list[int]], list[tuple[list[int], list[int], list[int]]]]:
    """``graph`` with each chain (of :func:`straight_chains`) a dual carriageway ``gap_m[i]`` wide: every node of the
    chain becomes a right and a left node with a median opening between, the roads of the chain a one-way road
    forward on the right and one back on the left, the other roads at a chain node attached to the side they leave
    on. Returns the graph, old edge -> new edges, and per chain (right, left, openings) new edge ids."""
    nodes = graph.nodes[["x", "y", "lon", "lat"]].copy()
    records, geometry = records_of(graph), [c.copy() for c in graph.geometry]
    in_chain = {e for chain in chains for e, _ in chain}
    keep = [e for e in range(graph.num_edges) if e not in in_chain]
    new_records = [records[e] for e in keep]
    new_geometry = [geometry[e] for e in keep]
    old_to_new = {e: [i] for i, e in enumerate(keep)}
    next_id = int(max(graph.nodes.index)) + 1
    duals = []
    for chain, gap in zip(chains, gap_m):
        path_nodes = [f for _, f in chain] + [graph.other_end(chain[-1][0], chain[-1][1])]
        centre = np.concatenate([graph.edge_coords(e, f)[:-1] for e, f in chain] + [graph.edge_coords(*chain[-1])[-1:]])
        normal_at_node = {}
        cuts = np.cumsum([0] + [len(graph.edge_coords(e, f)) - 1 for e, f in chain])
        centre_normals = normals(centre)
        for k in range(len(path_nodes)):
            normal_at_node[k] = centre_normals[cuts[k]]
        side = {}
        for k, node in enumerate(path_nodes):
            right, left = next_id, next_id + 1
            next_id += 2
            base = nodes.loc[node, ["x", "y"]].to_numpy(float)
            n = normal_at_node[k]
            nodes.loc[right, ["x", "y", "lon", "lat"]] = [*(base + 0.5 * gap * n), 0.0, 0.0]
            nodes.loc[left, ["x", "y", "lon", "lat"]] = [*(base - 0.5 * gap * n), 0.0, 0.0]
            side[k] = (right, left)
        index_of = {node: k for k, node in enumerate(path_nodes)}
        # other roads at chain nodes: attach to the side they leave on
        for i, e in enumerate(keep):
            rec, coords = new_records[i], new_geometry[i]
            for end in ("u", "v"):
                node = int(rec[end])
                if node not in index_of:
                    continue
                k = index_of[node]
                pts = coords if end == "u" else coords[::-1]
                leave = pts[min(1, len(pts) - 1)] - pts[0]
                r, l_ = side[k]
                chosen = r if float(np.dot(leave, normal_at_node[k])) >= 0 else l_
                rec[end] = chosen
                pts = pts.copy()
                pts[0] = nodes.loc[chosen, ["x", "y"]].to_numpy(float)
                new_geometry[i] = pts if end == "u" else pts[::-1]
                coords = new_geometry[i]
        right_ids, left_ids, openings = [], [], []
        for k, (e, f) in enumerate(chain):
            c = graph.edge_coords(e, f)
            n = normals(c)
            n[0], n[-1] = normal_at_node[k], normal_at_node[k + 1]
            r_coords = c + 0.5 * gap * n
            l_coords = (c - 0.5 * gap * n)[::-1]
            base = {k2: records[e][k2] for k2 in ("highway", "name", "osm_way_ids", "lanes", "width_m")}
            new_records.append({**base, "u": side[k][0], "v": side[k + 1][0], "oneway": 1})
            new_geometry.append(r_coords)
            new_records.append({**base, "u": side[k + 1][1], "v": side[k][1], "oneway": 1})
            new_geometry.append(l_coords)
            right_ids.append(len(new_records) - 2)
            left_ids.append(len(new_records) - 1)
            old_to_new[e] = [len(new_records) - 2, len(new_records) - 1]
        for k in range(len(path_nodes)):
            r, l_ = side[k]
            new_records.append({"highway": "service", "name": "median opening", "osm_way_ids": "", "lanes": np.nan,
                                "width_m": np.nan, "u": r, "v": l_, "oneway": 0})
            new_geometry.append(np.array([nodes.loc[r, ["x", "y"]].to_numpy(float), nodes.loc[l_, ["x", "y"]].to_numpy(float)]))
            openings.append(len(new_records) - 1)
        duals.append((right_ids, left_ids, openings))
    return build_graph(nodes, new_records, new_geometry, graph), old_to_new, duals


def add_detours(graph: RoadGraph, share: float, depth_m: tuple[float, float], rng: np.random.Generator
                ) -> tuple[RoadGraph, dict[int, list[int]], set[int]]:
    """``graph`` with a service-road loop off ``share`` of the roads (those >= 80 m): the road is split at two
    points 30-50 m apart and a two-way loop of ``depth_m`` goes out to the right and back between them. Returns the
    graph, old edge -> the pieces it was split into, and the loop's edge ids."""
    nodes = graph.nodes[["x", "y", "lon", "lat"]].copy()
    records, geometry = records_of(graph), [c.copy() for c in graph.geometry]
    long_enough = [e for e in range(graph.num_edges) if graph.edges.length_m.iat[e] >= 80.0
                   and graph.edges.u.iat[e] != graph.edges.v.iat[e]]
    count = min(len(long_enough), max(1, round(share * graph.num_edges)))
    chosen = set(rng.choice(long_enough, size=count, replace=False).tolist()) if long_enough else set()
    new_records, new_geometry, old_to_new, detours = [], [], {}, set()
    next_id = int(max(graph.nodes.index)) + 1
    for e in range(graph.num_edges):
        if e not in chosen:
            old_to_new[e] = [len(new_records)]
            new_records.append(records[e])
            new_geometry.append(geometry[e])
            continue
        coords = densify(geometry[e], 1.0)
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
        width = rng.uniform(30.0, 50.0)
        a_m = rng.uniform(20.0, cum[-1] - 20.0 - width) if cum[-1] > 40.0 + width else 0.5 * (cum[-1] - width)
        ia, ib = int(np.searchsorted(cum, a_m)), int(np.searchsorted(cum, a_m + width))
        a, b = next_id, next_id + 1
        next_id += 2
        for node, i in ((a, ia), (b, ib)):
            nodes.loc[node, ["x", "y", "lon", "lat"]] = [*coords[i], 0.0, 0.0]
        pieces = [(records[e]["u"], a, coords[: ia + 1]), (a, b, coords[ia: ib + 1]), (b, records[e]["v"], coords[ib:])]
        old_to_new[e] = []
        for u, v, c in pieces:
            old_to_new[e].append(len(new_records))
            new_records.append({**records[e], "u": u, "v": v})
            new_geometry.append(c)
        depth = rng.uniform(*depth_m)
        n = normals(coords)
        p1, p2 = coords[ia] + depth * n[ia], coords[ib] + depth * n[ib]
        loop = np.array([coords[ia], p1, p2, coords[ib]])
        detours.add(len(new_records))
        new_records.append({"highway": "service", "name": "parking", "osm_way_ids": "", "lanes": np.nan,
                            "width_m": np.nan, "u": a, "v": b, "oneway": 0})
        new_geometry.append(densify(loop, 2.0))
    return build_graph(nodes, new_records, new_geometry, graph), old_to_new, detours


def drop_roads(graph: RoadGraph, share: float, rng: np.random.Generator) -> tuple[RoadGraph, dict[int, int]]:
    """``graph`` without ``share`` of its roads, never one whose loss disconnects it; returns the graph and
    new edge -> old edge."""
    g = nx.MultiGraph()
    g.add_nodes_from(graph.nodes.index)
    for e in range(graph.num_edges):
        g.add_edge(int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e]), key=e)
    target = max(1, round(share * graph.num_edges))
    dropped: set[int] = set()
    for e in rng.permutation(graph.num_edges):
        if len(dropped) >= target:
            break
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        g.remove_edge(u, v, key=int(e))
        if u == v or nx.has_path(g, u, v):
            dropped.add(int(e))
        else:
            g.add_edge(u, v, key=int(e))
    keep = [e for e in range(graph.num_edges) if e not in dropped]
    records = records_of(graph)
    return (build_graph(graph.nodes.copy(), [records[e] for e in keep], [graph.geometry[e].copy() for e in keep], graph),
            dict(enumerate(keep)))


def crop_graph(graph: RoadGraph, radius_m: float) -> RoadGraph:
    """The largest connected part of the roads of ``graph`` with both ends within ``radius_m`` of its middle (the
    median node)."""
    xy = graph.nodes[["x", "y"]].to_numpy(float)
    inside = set(graph.nodes.index[np.hypot(*(xy - np.median(xy, axis=0)).T) <= radius_m].tolist())
    g = nx.MultiGraph()
    for e in range(graph.num_edges):
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        if u in inside and v in inside:
            g.add_edge(u, v, key=e)
    if not g.number_of_edges():
        raise ValueError(f"no road within {radius_m} m of the map's middle")
    largest = max(nx.connected_components(g), key=len)
    keep = sorted(k for u, v, k in g.edges(keys=True) if u in largest)
    records = records_of(graph)
    return build_graph(graph.nodes.copy(), [records[e] for e in keep], [graph.geometry[e].copy() for e in keep], graph)
