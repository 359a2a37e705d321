import networkx as nx
import numpy as np
import pytest

from osm_fixtures import write_cross
from topoloc.errors import InputError
from topoloc.graph.build_graph import graph_stats
from topoloc.graph.from_osm import build_road_graph, utm_crs
from topoloc.graph.road_graph import RoadGraph
from topoloc.osm.reader import DRIVABLE_HIGHWAY_CLASSES


@pytest.fixture()
def cross(tmp_path):
    graph, facts = build_road_graph(str(write_cross(tmp_path / "cross.osm")), DRIVABLE_HIGHWAY_CLASSES, 20.0)
    return graph, facts


def test_nodes_are_intersections_dead_ends_and_direction_changes(cross):
    graph, facts = cross
    assert sorted(graph.nodes.index) == [1, 2, 5, 6, 10, 11, 30]
    assert graph.nodes.degree.to_dict() == {1: 4, 2: 1, 5: 2, 6: 1, 10: 2, 11: 1, 30: 1}
    assert facts["components"] == 2 and facts["dropped_edges"] == 1  # the far-away way
    assert graph.crs == "EPSG:32631"


def test_edges_have_stable_ids_geometry_length_and_direction(cross):
    graph, _ = cross
    assert list(zip(graph.edges.u, graph.edges.v)) == [(1, 2), (1, 5), (1, 6), (1, 30), (5, 10), (10, 11)]
    # Edge 0 runs from node 1 through shape point 3 to node 2: two pieces of ~55.7 m.
    assert len(graph.geometry[0]) == 3
    assert graph.edges.length_m[0] == pytest.approx(111.3, abs=0.5)
    assert graph.edges.virtual_nodes[0] == 5  # 20, 40, 60, 80, 100 m
    # The service road is one-way 10 -> 9 -> 5, i.e. against u -> v = 5 -> 10.
    assert graph.edges.oneway.tolist() == [0, 0, 0, 0, -1, 0]
    # The overlapping ways 101 and 102 make one road; both ids are kept.
    assert graph.edges.osm_way_ids[2] == "101"
    assert graph.edges.osm_way_ids[3] == "101;107"
    # lanes / width tags: per road, the value of most of its tagged segments (way 107 is untagged)
    assert graph.edges.lanes.fillna(0).tolist() == [2, 2, 0, 0, 0, 1]
    assert graph.edges.width_m.fillna(0).tolist() == [0, 0, 8.5, 8.5, 0, 0]
    assert np.allclose(graph.geometry[3][0], graph.nodes.loc[1, ["x", "y"]].to_numpy(float))


def test_highway_class_filter_and_private_roads(tmp_path):
    path = str(write_cross(tmp_path / "cross.osm"))
    graph, _ = build_road_graph(path, ["residential"], 20.0)
    assert (graph.edges.highway == "residential").all()
    assert 10 not in graph.nodes.index  # only reachable through the service road
    graph, _ = build_road_graph(path, DRIVABLE_HIGHWAY_CLASSES, 20.0, exclude_private=True)
    assert 11 not in graph.nodes.index and graph.nodes.degree[10] == 1


def test_unknown_class_and_bad_spacing_name_the_key(tmp_path):
    path = str(write_cross(tmp_path / "cross.osm"))
    with pytest.raises(InputError, match="graph.highway_classes"):
        build_road_graph(path, ["residential", "footway"], 20.0)
    with pytest.raises(InputError, match="graph.virtual_node_spacing_m"):
        build_road_graph(path, ["residential"], 0.0)
    with pytest.raises(InputError, match="graph.crs"):
        build_road_graph(path, ["residential"], 20.0, crs="EPSG:4326")


def test_graphml_round_trip(cross, tmp_path):
    graph, _ = cross
    graph.save_graphml(tmp_path / "g.graphml")
    loaded = RoadGraph.load(tmp_path / "g.graphml")
    assert loaded.crs == graph.crs and loaded.virtual_node_spacing_m == 20.0
    assert loaded.edges.drop(columns=["length_m"]).equals(graph.edges.drop(columns=["length_m"]))
    assert np.allclose(loaded.edges.length_m, graph.edges.length_m)
    for a, b in zip(loaded.geometry, graph.geometry):
        assert np.allclose(a, b, atol=1e-6)
    assert loaded.graph.number_of_edges() == 6 and nx.is_connected(loaded.graph)
    assert loaded.edge_coords(0, from_node=2)[0] == pytest.approx(graph.geometry[0][-1])
    assert loaded.other_end(0, 1) == 2
    segments = loaded.virtual_segments()
    assert len(segments) == loaded.edges.virtual_nodes.sum() + loaded.num_edges
    first = segments[segments.edge_id == 0]
    assert first.start_m.tolist()[:2] == [0.0, 20.0] and first.end_m.iloc[-1] == pytest.approx(loaded.edges.length_m[0])


def test_load_rejects_other_files(tmp_path):
    (tmp_path / "x.graphml").write_text("not xml")
    with pytest.raises(InputError, match="x.graphml"):
        RoadGraph.load(tmp_path / "x.graphml")
    with pytest.raises(InputError, match="build_graph"):
        RoadGraph.load(tmp_path / "missing.graphml")


def test_utm_zone():
    assert utm_crs(24.94, 60.17) == "EPSG:32635"
    assert utm_crs(8.39, 48.98) == "EPSG:32632"
    assert utm_crs(-58.4, -34.6) == "EPSG:32721"


def test_kitti00_graph_matches_the_reference_counts(kitti00):
    graph, facts = build_road_graph(str(kitti00 / "map" / "kitti_00.osm"), DRIVABLE_HIGHWAY_CLASSES, 20.0)
    stats = graph_stats(graph, facts)
    # osmnx (largest component) gives 151 nodes / 208 edges; it counts two OSM ways mapped
    # over one stretch twice, which this builder merges (see tests of overlapping ways).
    assert 145 <= stats["nodes"] <= 170 and 200 <= stats["edges"] <= 225
    assert stats["intersections"] >= 100 and stats["crs"] == "EPSG:32632"
    assert nx.is_connected(graph.graph)


def test_helsinki_graph(helsinki_pbf):
    graph, facts = build_road_graph(str(helsinki_pbf), DRIVABLE_HIGHWAY_CLASSES, 20.0)
    assert nx.is_connected(graph.graph)
    assert 300 <= len(graph.nodes) <= 500 and 25 <= graph.edges.length_m.sum() / 1000 <= 40
    # Ways cut at the extract's border are kept as the parts that have locations.
    assert facts["missing_node_refs"] > 0
