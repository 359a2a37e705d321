"""The drivable road network of an OSM file as a topological :class:`~topoloc.graph.road_graph.RoadGraph`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import networkx as nx
import numpy as np
import pandas as pd
import pyproj

from topoloc.errors import InputError
from topoloc.geometry import virtual_node_count
from topoloc.graph.road_graph import EDGE_COLUMNS, RoadGraph
from topoloc.graph.topology import topological_roads
from topoloc.osm.reader import DRIVABLE_HIGHWAY_CLASSES, read_road_network


def utm_crs(lon: float, lat: float) -> str:
    """The WGS84 UTM zone CRS (``EPSG:326zz`` / ``EPSG:327zz``) that contains ``lon``, ``lat``."""
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    return f"EPSG:{(32600 if lat >= 0 else 32700) + zone}"


def build_road_graph(
    osm_path: str,
    highway_classes: Sequence[str],
    virtual_node_spacing_m: float,
    crs: str | None = None,
    exclude_private: bool = False,
) -> tuple[RoadGraph, dict[str, Any]]:
    """Read ``osm_path`` and build the largest connected drivable road graph.

    Returns the graph and facts about the build (components dropped, CRS chosen).
    """
    unknown = sorted(set(highway_classes) - set(DRIVABLE_HIGHWAY_CLASSES))
    if unknown or not highway_classes:
        raise InputError("graph.highway_classes", f"unknown or no highway classes {unknown}; choose from {list(DRIVABLE_HIGHWAY_CLASSES)}")
    if virtual_node_spacing_m <= 0:
        raise InputError("graph.virtual_node_spacing_m", f"must be positive, got {virtual_node_spacing_m}")
    network = read_road_network(osm_path, highway_classes, exclude_private)
    roads = topological_roads(network)

    lonlat = np.array([network.lonlat[n] for n in network.lonlat])
    if crs is None:
        crs = utm_crs(*np.median(lonlat, axis=0))
    try:
        to_metric = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    except pyproj.exceptions.CRSError as err:
        raise InputError("graph.crs", f"unknown CRS '{crs}' ({err})") from err
    if not pyproj.CRS(crs).is_projected:
        raise InputError("graph.crs", f"'{crs}' is not a projected (metric) CRS")

    topo = nx.MultiGraph()
    for index, road in enumerate(roads):
        topo.add_edge(road.nodes[0], road.nodes[-1], key=index)
    components = sorted(nx.connected_components(topo), key=lambda c: (len(c), -min(c)), reverse=True)
    largest = components[0]
    roads = [road for road in roads if road.nodes[0] in largest]

    node_ids = sorted({n for road in roads for n in (road.nodes[0], road.nodes[-1])})
    lon, lat = np.array([network.lonlat[n] for n in node_ids]).T
    x, y = to_metric.transform(lon, lat)
    nodes = pd.DataFrame({"x": x, "y": y, "lon": lon, "lat": lat}, index=pd.Index(node_ids, name="node_id"))
    geometry = []
    records = []
    for road in roads:
        road_lon, road_lat = np.array([network.lonlat[n] for n in road.nodes]).T
        coords = np.column_stack(to_metric.transform(road_lon, road_lat))
        length = float(np.hypot(*np.diff(coords, axis=0).T).sum())
        geometry.append(coords)
        records.append((road.nodes[0], road.nodes[-1], length, road.highway, road.name, road.oneway,
                        ";".join(map(str, road.osm_way_ids)), virtual_node_count(length, virtual_node_spacing_m),
                        road.lanes, road.width_m))
    edges = pd.DataFrame(records, columns=EDGE_COLUMNS)
    edges.index.name = "edge_id"
    degree = pd.concat([edges.u, edges.v]).value_counts()
    nodes["degree"] = degree.reindex(nodes.index).astype(int)
    graph = RoadGraph(nodes, edges, geometry, crs, float(virtual_node_spacing_m))
    facts = {
        "crs": crs,
        "components": len(components),
        "dropped_edges": int(topo.number_of_edges() - len(edges)),
        "osm_ways": len(network.ways),
        "missing_node_refs": network.missing_node_refs,
    }
    return graph, facts
