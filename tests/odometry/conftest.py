"""Road graphs for the odometry tests: the real kitti00 map, and a small hand-made grid."""

from pathlib import Path

import pytest

from tests.conftest import write_osm
from topoloc.graph.from_osm import build_road_graph

GRAPH_CLASSES = ["primary", "secondary", "tertiary", "unclassified", "residential", "living_street", "service"]


@pytest.fixture(scope="session")
def kitti00_graph(kitti00, tmp_path_factory) -> Path:
    """GraphML of the kitti00 map, as build_graph writes it."""
    graph, _ = build_road_graph(str(kitti00 / "map" / "kitti_00.osm"), GRAPH_CLASSES, 20.0)
    path = tmp_path_factory.mktemp("kitti00") / "graph.graphml"
    graph.save_graphml(path)
    return path


@pytest.fixture(scope="session")
def grid_graph(tmp_path_factory) -> Path:
    """A 4 x 4 grid of residential streets, about 150 m apart, near Karlsruhe."""
    tmp = tmp_path_factory.mktemp("grid")
    nodes, ways = {}, []
    for i in range(4):
        for j in range(4):
            nodes[1 + i * 4 + j] = (8.39 + 0.002 * j, 48.98 + 0.00135 * i)
    way = 100
    for i in range(4):
        ways.append((way, [1 + i * 4 + j for j in range(4)], {"highway": "residential"}))
        ways.append((way + 1, [1 + j * 4 + i for j in range(4)], {"highway": "residential"}))
        way += 2
    osm = write_osm(tmp / "grid.osm", nodes, ways)
    graph, _ = build_road_graph(str(osm), GRAPH_CLASSES, 20.0)
    path = tmp / "graph.graphml"
    graph.save_graphml(path)
    return path
