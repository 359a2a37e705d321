"""The topological road graph that every later stage reads.

A :class:`RoadGraph` is an undirected multigraph: nodes are intersections and
dead ends (OSM node ids), edges are roads with stable integer ids, metric
geometry (in a projected CRS) from ``u`` to ``v`` and a length. Virtual nodes
every ``virtual_node_spacing_m`` split each road into virtual segments.

It is stored as GraphML (geometry as WKT) so that other tools can open it too.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd
import shapely
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.geometry import virtual_node_offsets
from topoloc.io import atomic_path

EDGE_COLUMNS = ["u", "v", "length_m", "highway", "name", "oneway", "osm_way_ids", "virtual_nodes", "lanes", "width_m"]


@dataclass
class RoadGraph:
    """Roads between intersections, in metres.

    Attributes
    ----------
    nodes
        Indexed by ``node_id`` (OSM id): ``x``, ``y`` (projected), ``lon``, ``lat``, ``degree``.
    edges
        Indexed by ``edge_id`` (0..E-1): ``u``, ``v``, ``length_m``, ``highway``,
        ``name``, ``oneway`` (+1 only u->v, -1 only v->u, 0 both),
        ``osm_way_ids``, ``virtual_nodes``, ``lanes`` and ``width_m`` (the OSM ``lanes`` and ``width`` tags, NaN
        where untagged; :func:`topoloc.render.textures.carriageway_width` turns them into the road's width).
    geometry
        Per edge id, the ``(n, 2)`` polyline from ``u`` to ``v``.
    crs
        The projected CRS of ``x``, ``y`` and ``geometry``.
    virtual_node_spacing_m
        Spacing of the virtual nodes.
    """

    nodes: pd.DataFrame
    edges: pd.DataFrame
    geometry: list[NDArray[np.float64]]
    crs: str
    virtual_node_spacing_m: float
    meta: dict[str, str] = field(default_factory=dict)

    @cached_property
    def graph(self) -> nx.MultiGraph:
        """The networkx view: edge keys are edge ids; edges carry ``edge_id`` and ``length``."""
        graph = nx.MultiGraph(crs=self.crs)
        graph.add_nodes_from(self.nodes.index)
        for edge_id, (u, v, length) in enumerate(zip(self.edges.u, self.edges.v, self.edges.length_m)):
            graph.add_edge(u, v, key=edge_id, edge_id=edge_id, length=length)
        return graph

    @property
    def num_edges(self) -> int:
        """Number of roads (classes of the trajectory model)."""
        return len(self.edges)

    def edge_coords(self, edge_id: int, from_node: int | None = None) -> NDArray[np.float64]:
        """Polyline of ``edge_id``, oriented to start at ``from_node`` (default: at ``u``)."""
        coords = self.geometry[edge_id]
        if from_node is None or from_node == self.edges.u.iat[edge_id]:
            return coords
        if from_node != self.edges.v.iat[edge_id]:
            raise ValueError(f"node {from_node} is not an end of edge {edge_id}")
        return coords[::-1]

    def other_end(self, edge_id: int, node: int) -> int:
        """The end of ``edge_id`` that is not ``node`` (``node`` itself for a loop)."""
        u, v = self.edges.u.iat[edge_id], self.edges.v.iat[edge_id]
        return int(v if node == u else u)

    def virtual_segments(self) -> pd.DataFrame:
        """One row per virtual segment: ``segment_id``, ``edge_id``, ``index`` from ``u``, ``start_m``, ``end_m``."""
        rows = []
        for edge_id, length in enumerate(self.edges.length_m):
            cuts = np.concatenate([[0.0], virtual_node_offsets(length, self.virtual_node_spacing_m), [length]])
            for index, (start, end) in enumerate(zip(cuts[:-1], cuts[1:])):
                rows.append((edge_id, index, start, end))
        table = pd.DataFrame(rows, columns=["edge_id", "index", "start_m", "end_m"])
        table.index.name = "segment_id"
        return table

    def save_graphml(self, path: str | Path) -> None:
        """Write the graph as GraphML (atomically), geometry as WKT in the projected CRS."""
        graph = nx.MultiGraph(crs=self.crs, virtual_node_spacing_m=self.virtual_node_spacing_m, **self.meta)
        for node_id, row in self.nodes.iterrows():
            graph.add_node(int(node_id), x=float(row.x), y=float(row.y), lon=float(row.lon), lat=float(row.lat))
        for edge_id, row in self.edges.iterrows():
            graph.add_edge(
                int(row.u),
                int(row.v),
                key=int(edge_id),
                edge_id=int(edge_id),
                length=float(row.length_m),
                highway=str(row.highway),
                name=str(row["name"]),
                oneway=int(row.oneway),
                osm_way_ids=str(row.osm_way_ids),
                virtual_nodes=int(row.virtual_nodes),
                lanes=float(row.lanes),
                width_m=float(row.width_m),
                geometry=shapely.LineString(self.geometry[edge_id]).wkt,
            )
        with atomic_path(path) as tmp:
            nx.write_graphml(graph, tmp)

    @classmethod
    def load(cls, path: str | Path) -> RoadGraph:
        """Read a graph written by :meth:`save_graphml`; InputError naming the file if it is not one."""
        path = Path(path)
        try:
            graph = nx.read_graphml(path, node_type=int, force_multigraph=True)
        except FileNotFoundError as err:
            raise InputError(path, "road graph not found (run the build_graph stage first)") from err
        except Exception as err:  # networkx raises several parser errors
            raise InputError(path, f"not a road graph GraphML file ({err})") from err
        if "crs" not in graph.graph or "virtual_node_spacing_m" not in graph.graph:
            raise InputError(path, "GraphML file lacks the crs / virtual_node_spacing_m attributes of a topoloc road graph")
        node_rows = {n: d for n, d in graph.nodes(data=True)}
        edge_rows = sorted((d["edge_id"], u, v, d) for u, v, d in graph.edges(data=True))
        geometry = []
        records = []
        for edge_id, u, v, data in edge_rows:
            coords = np.asarray(shapely.from_wkt(data["geometry"]).coords, dtype=float)
            # networkx may hand the ends back swapped for undirected graphs: restore u -> v.
            start = np.array([node_rows[u]["x"], node_rows[u]["y"]])
            if u != v and np.hypot(*(coords[0] - start)) > np.hypot(*(coords[-1] - start)):
                u, v = v, u
            geometry.append(coords)
            records.append((u, v, data["length"], data["highway"], data.get("name", ""), data["oneway"],
                            data["osm_way_ids"], data["virtual_nodes"], float(data.get("lanes", "nan")),
                            float(data.get("width_m", "nan"))))
        if [r[0] for r in edge_rows] != list(range(len(edge_rows))):
            raise InputError(path, "edge ids are not 0..E-1")
        edges = pd.DataFrame(records, columns=EDGE_COLUMNS)
        edges.index.name = "edge_id"
        nodes = pd.DataFrame.from_dict(node_rows, orient="index")[["x", "y", "lon", "lat"]]
        nodes.index.name = "node_id"
        nodes = nodes.sort_index()
        nodes["degree"] = pd.Series(dict(graph.degree())).reindex(nodes.index).astype(int)
        meta = {k: v for k, v in graph.graph.items() if k not in {"crs", "virtual_node_spacing_m"}}
        return cls(nodes, edges, geometry, str(graph.graph["crs"]), float(graph.graph["virtual_node_spacing_m"]), meta)
