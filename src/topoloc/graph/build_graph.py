"""Stage ``build_graph``: the drivable road network of a region as a topological graph."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from topoloc.graph.from_osm import build_road_graph
from topoloc.graph.plot import plot_road_graph
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json

log = logging.getLogger(__name__)


def graph_stats(graph: RoadGraph, facts: dict[str, Any]) -> dict[str, Any]:
    """Summary numbers of a road graph, as written to ``stats.json``."""
    degree = graph.nodes.degree
    return {
        "nodes": len(graph.nodes),
        "intersections": int((degree >= 3).sum()),
        "dead_ends": int((degree == 1).sum()),
        "edges": graph.num_edges,
        "virtual_nodes": int(graph.edges.virtual_nodes.sum()),
        "virtual_segments": int(graph.edges.virtual_nodes.sum() + graph.num_edges),
        "road_km": round(float(graph.edges.length_m.sum()) / 1000.0, 3),
        "oneway_edges": int((graph.edges.oneway != 0).sum()),
        "self_loops": int((graph.edges.u == graph.edges.v).sum()),
        "virtual_node_spacing_m": graph.virtual_node_spacing_m,
        **facts,
    }


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Build the road graph from ``inputs['osm']`` and write graph, tables, stats and map figure.

    ``conf`` is the ``graph`` config slice: ``highway_classes``,
    ``virtual_node_spacing_m``, ``crs`` (null: the UTM zone of the data),
    ``exclude_private_roads`` and ``figure`` options.
    """
    graph, facts = build_road_graph(
        inputs["osm"], conf["highway_classes"], conf["virtual_node_spacing_m"], conf["crs"], conf["exclude_private_roads"]
    )
    stats = graph_stats(graph, facts)
    log.info("road graph: %d nodes, %d edges, %.1f km, %d virtual nodes (%s)",
             stats["nodes"], stats["edges"], stats["road_km"], stats["virtual_nodes"], stats["crs"])
    graph.save_graphml(outputs["graph"])
    table = graph.edges.copy()
    table["geometry_wkt"] = [_wkt(coords) for coords in graph.geometry]
    for name, frame in (("edges", table), ("nodes", graph.nodes), ("virtual_segments", graph.virtual_segments())):
        with atomic_path(outputs[name]) as tmp:
            frame.to_csv(tmp, float_format="%.3f")
    title = f"Road graph: {stats['edges']} roads, {stats['intersections']} intersections, {stats['dead_ends']} dead ends"
    plot_road_graph(graph, outputs["figure"], title=title, label_edges=conf["figure"]["label_edges"])
    write_json(outputs["stats"], stats)
    return {k: float(v) for k, v in stats.items() if isinstance(v, int | float)}


def _wkt(coords: np.ndarray) -> str:
    return "LINESTRING (" + ", ".join(f"{x:.2f} {y:.2f}" for x, y in coords) + ")"
