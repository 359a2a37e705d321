"""Fixtures of the drive tests: the hand-made town of the render tests, its routes, and a straight road."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import make_config, write_osm
from tests.render.conftest import lonlat, town  # noqa: F401 (the town fixture, re-exported)
from topoloc.drive.lanes import DriveRoute, build_route, plan_route
from topoloc.graph.from_osm import build_road_graph
from topoloc.graph.road_graph import RoadGraph
from topoloc.render.scene import Scene, scene_for_path

#: Node pairs of the town's evaluation routes (grid corners and edge midpoints, by position): straight on,
#: a right turn, a left turn.
TOWN_ROUTES = {"straight": ((0.0, 150.0), (300.0, 150.0)), "right": ((0.0, 150.0), (150.0, 0.0)),
               "left": ((150.0, 0.0), (0.0, 150.0))}


def drive_conf(**sections) -> dict:
    """The ``drive`` slice (schema defaults) with sections updated."""
    conf = make_config()["drive"]
    for key, value in sections.items():
        conf[key] = {**conf[key], **value} if isinstance(value, dict) else value
    return conf


def node_at(graph: RoadGraph, x: float, y: float) -> int:
    """The graph node nearest to the town position (x, y) metres from its south-west corner."""
    ref = graph.nodes[["x", "y"]].to_numpy(float)
    origin = ref.min(axis=0)
    return int(graph.nodes.index[int(np.argmin(np.hypot(*(ref - origin - [x, y]).T)))])


def town_route(graph: RoadGraph, name: str, drive: dict) -> DriveRoute:
    """One of :data:`TOWN_ROUTES` as a drive route."""
    (a, b) = TOWN_ROUTES[name]
    edges, froms = plan_route(graph, node_at(graph, *a), node_at(graph, *b))
    return build_route(graph, edges, froms, drive["lane"]["smoothing_m"], drive["lane"]["margin_m"],
                       min_radius_m=drive["lane"]["min_radius_m"])


@pytest.fixture(scope="session")
def town_graph(town) -> RoadGraph:  # noqa: F811 (the fixture re-exported above)
    """The town's road graph."""
    return RoadGraph.load(town["graph"])


def route_scene(osm: Path, graph: RoadGraph, route: DriveRoute) -> Scene:
    """The buildings and roads around a route (default render settings)."""
    render = make_config()["render"]
    return scene_for_path(str(osm), graph, route.xy, {**render["buildings"], "view_distance_m": 100.0}, 0)


@pytest.fixture(scope="session")
def straight_road(tmp_path_factory) -> dict:
    """A straight two-way residential road of 400 m (with a crossing side street at 200 m) and its graph."""
    tmp = tmp_path_factory.mktemp("straight")
    nodes = {1: lonlat(0.0, 0.0), 2: lonlat(200.0, 0.0), 3: lonlat(400.0, 0.0), 4: lonlat(200.0, -60.0),
             5: lonlat(200.0, 60.0)}
    ways = [(10, [1, 2, 3], {"highway": "residential", "name": "Long"}),
            (11, [4, 2, 5], {"highway": "residential", "name": "Cross"})]
    osm = write_osm(tmp / "straight.osm", nodes, ways)
    graph, _ = build_road_graph(str(osm), ["residential"], 20.0)
    return {"osm": osm, "graph": graph}
