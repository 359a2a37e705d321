"""Hand-made road graphs for the trajectory tests."""

from __future__ import annotations

import numpy as np
import pandas as pd

from topoloc.graph.road_graph import EDGE_COLUMNS, RoadGraph


def make_graph(coords: dict[int, tuple[float, float]], edges: list[tuple], spacing: float = 20.0) -> RoadGraph:
    """Roads between ``coords``; ``edges`` are ``(u, v)``, ``(u, v, oneway)`` or ``(u, v, oneway, via)`` (ids in
    order), straight or through the points ``via`` (a bend inside the road)."""
    nodes = pd.DataFrame({"x": [c[0] for c in coords.values()], "y": [c[1] for c in coords.values()],
                          "lon": 0.0, "lat": 0.0}, index=pd.Index(list(coords), name="node_id"))
    records, geometry = [], []
    for edge in edges:
        u, v = edge[:2]
        oneway = edge[2] if len(edge) > 2 else 0
        pts = np.array([coords[u], *(edge[3] if len(edge) > 3 else ()), coords[v]], dtype=float)
        length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
        geometry.append(pts)
        records.append((u, v, length, "residential", "", oneway, "1", 0, np.nan, np.nan))
    frame = pd.DataFrame(records, columns=EDGE_COLUMNS)
    frame.index.name = "edge_id"
    degree = pd.Series(0, index=nodes.index)
    for u, v in zip(frame.u, frame.v):
        degree[u] += 1
        degree[v] += 1
    nodes["degree"] = degree
    return RoadGraph(nodes, frame, geometry, "EPSG:3067", spacing)


def random_graph(seed: int, n: int = 12, extra: int = 6) -> RoadGraph:
    """A connected planar-ish graph: a random spanning tree plus ``extra`` edges, irregular lengths."""
    rng = np.random.default_rng(seed)
    coords = {i: (float(x), float(y)) for i, (x, y) in enumerate(rng.uniform(0, 400, size=(n, 2)))}
    edges: list[tuple] = []
    seen = set()
    for i in range(1, n):
        j = int(rng.integers(0, i))
        edges.append((j, i))
        seen.add((j, i))
    while extra:
        a, b = sorted(int(v) for v in rng.choice(n, 2, replace=False))
        if (a, b) not in seen:
            edges.append((a, b))
            seen.add((a, b))
            extra -= 1
    return make_graph(coords, edges)
