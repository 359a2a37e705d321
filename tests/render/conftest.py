"""A small hand-made town for the render tests: a 3 x 3 street grid with building footprints.

Streets run every 150 m near Karlsruhe (UTM 32N); three of the four blocks carry a ring of buildings
(12 m deep, 18-30 m long, 8 m from the street centre lines), with a ``height`` tag, a
``building:levels`` tag or no height at all; the north-east block has none, so procedural facades fill
its street sides.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import make_config, write_osm
from topoloc.graph.from_osm import build_road_graph

LON0, LAT0 = 8.39, 48.98
M_PER_DEG_LAT = 111_200.0
M_PER_DEG_LON = 111_320.0 * np.cos(np.radians(LAT0))
STREETS_M = (0.0, 150.0, 300.0)
EMPTY_BLOCK = (1, 1)


def lonlat(x: float, y: float) -> tuple[float, float]:
    """WGS84 of a point ``x`` m east and ``y`` m north of the grid's south-west corner."""
    return LON0 + x / M_PER_DEG_LON, LAT0 + y / M_PER_DEG_LAT


def town_osm(path: Path) -> Path:
    """Write the town (streets and buildings) as OSM XML."""
    nodes: dict[int, tuple[float, float]] = {}
    ways = []
    for i, y in enumerate(STREETS_M):
        for j, x in enumerate(STREETS_M):
            nodes[1 + 3 * i + j] = lonlat(x, y)
    for k in range(3):
        ways.append((100 + k, [1 + 3 * k + j for j in range(3)], {"highway": "residential", "name": f"Row {k}"}))
        ways.append((110 + k, [1 + 3 * i + k for i in range(3)], {"highway": "residential", "name": f"Col {k}"}))
    rng = np.random.default_rng(5)
    node_id, way_id = 1000, 1000
    for bi in range(2):
        for bj in range(2):
            if (bi, bj) == EMPTY_BLOCK:
                continue
            x0, y0 = STREETS_M[bj] + 8.0, STREETS_M[bi] + 8.0
            size = 150.0 - 16.0
            for side in range(4):
                s = 0.0
                while s < size - 18.0:
                    length = min(rng.uniform(18.0, 30.0), size - s)
                    a, b = s, s + length
                    corners = {0: [(a, 0), (b, 0), (b, 12), (a, 12)], 1: [(size, a), (size, b), (size - 12, b), (size - 12, a)],
                               2: [(a, size), (a, size - 12), (b, size - 12), (b, size)], 3: [(0, a), (12, a), (12, b), (0, b)]}[side]
                    refs = []
                    for cx, cy in corners:
                        nodes[node_id] = lonlat(x0 + cx, y0 + cy)
                        refs.append(node_id)
                        node_id += 1
                    kind = way_id % 3
                    tags = {"building": "yes", **({"height": f"{rng.uniform(10, 20):.1f}"} if kind == 0 else {}),
                            **({"building:levels": str(int(rng.integers(3, 7)))} if kind == 1 else {})}
                    ways.append((way_id, [*refs, refs[0]], tags))
                    way_id += 1
                    s = b + 3.0
    return write_osm(path, nodes, sorted(ways))


@pytest.fixture(scope="session")
def town(tmp_path_factory) -> dict[str, Path]:
    """The town's OSM file and its road graph (GraphML)."""
    tmp = tmp_path_factory.mktemp("town")
    osm = town_osm(tmp / "town.osm")
    graph, _ = build_road_graph(str(osm), ["residential"], 20.0)
    graph.save_graphml(tmp / "graph.graphml")
    return {"osm": osm, "graph": tmp / "graph.graphml"}


def render_conf(**overrides) -> dict:
    """The ``render`` config slice (schema defaults) with a short route, small sheets, and ``overrides``."""
    conf = make_config(render={"length_m": 160.0, "sheet": {"conditions": ["clear_noon", "night"], "frames": 2}})["render"]
    conf.update(overrides)
    return conf


def render_outputs(root: Path) -> dict[str, str]:
    """Output paths of render_drive under ``root``, as the rule names them."""
    names = {"left": "image_0", "right": "image_1", "calib": "calib.txt", "poses": "poses.txt", "times": "times.txt",
             "gps": "gps.csv", "route": "route.csv", "stats": "render.json", "sheet": "contact_sheet.png"}
    return {k: str(root / v) for k, v in names.items()}
