"""The driving simulator and the expert: episodes end as they should, runs repeat exactly, bad routes are refused."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import make_config, write_osm
from tests.drive.conftest import TOWN_ROUTES, drive_conf, node_at, route_scene, town_route
from tests.render.conftest import lonlat
from topoloc.drive.demonstrations import training_route
from topoloc.drive.drive_route import build_route
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.lane_geometry import DENSE_M, lane_curvature, lane_polyline, widen_bends
from topoloc.drive.route_planning import check_route, plan_route
from topoloc.drive.routes import random_drive_route, route_of_edges
from topoloc.drive.simulator import (
    OFF_ROAD,
    RUNNING,
    SUCCESS,
    WRONG_ROAD,
    Control,
    Simulator,
    VehicleSpec,
)
from topoloc.errors import InputError
from topoloc.graph.from_osm import build_road_graph
from topoloc.render.conditions import CONDITIONS
from topoloc.render.rig import StereoRig
from topoloc.render.scene import graph_roads
from topoloc.render.textures import carriageway_width, has_centre_line, road_width

RIG = StereoRig.kitti(64, 48, 0.54, 1.65)


def simulator(town, graph, name: str, drive: dict, length_m: float | None = None) -> Simulator:
    route = town_route(graph, name, drive)
    route = route.cut(length_m) if length_m else route
    return Simulator(route, route_scene(town["osm"], graph, route), RIG, VehicleSpec.from_conf(drive), 100.0)


def drive_expert(sim: Simulator, expert: Expert, condition: str, seed: int = 0) -> tuple[str, list[float]]:
    sim.reset(condition, seed)
    expert.reset()
    status, lateral = RUNNING, []
    while status == RUNNING:
        _, status = sim.step(expert.control(sim.state))
        lateral.append(sim.lateral)
    return status, lateral


def test_expert_completes_every_route_in_every_condition(town, town_graph):
    drive = drive_conf()
    for name in TOWN_ROUTES:
        sim = simulator(town, town_graph, name, drive, 175.0)  # through the intersection at 150 m
        assert sim.route.length_m > 170
        expert = Expert(sim.route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
        for condition in CONDITIONS:
            status, lateral = drive_expert(sim, expert, condition)
            assert status == SUCCESS, (name, condition)
            assert np.max(np.abs(lateral)) < 1.0  # stays in its lane, corners included
            assert sim.t < sim.max_steps


def test_turn_commands_come_from_the_graph(town_graph):
    drive = drive_conf()
    names = {name: sorted({int(c) for c in town_route(town_graph, name, drive).command}) for name in TOWN_ROUTES}
    assert names == {"straight": [0, 3], "right": [0, 2], "left": [0, 1]}  # follow + straight / right / left


def test_leaving_the_road_is_a_failure(town, town_graph):
    sim = simulator(town, town_graph, "straight", drive_conf())
    sim.reset("clear_noon", 0, speed=5.0)
    status, steps = RUNNING, 0
    while status == RUNNING:
        _, status = sim.step(Control(0.6, 0.3))
        steps += 1
    assert status == OFF_ROAD and steps < 40


def test_a_wrong_turn_is_a_failure(town, town_graph):
    drive = drive_conf()
    straight = simulator(town, town_graph, "straight", drive)
    turning = town_route(town_graph, "right", drive)  # same start, turns right where "straight" goes on
    expert = Expert(turning, straight.spec, ExpertSettings.from_conf(drive["expert"]))
    status, _ = drive_expert(straight, expert, "overcast")
    assert status == WRONG_ROAD
    assert 140 < straight.s < 175  # just past the intersection at 150 m


def test_episodes_are_deterministic_for_a_seed(town, town_graph):
    drive = drive_conf()
    sim = simulator(town, town_graph, "left", drive)

    def episode(seed: int) -> tuple[np.ndarray, np.ndarray]:
        obs = sim.reset("rain", seed, lateral_m=0.3, yaw_deg=2.0)
        rng = np.random.default_rng(seed)
        images, states = [obs.image], []
        for _ in range(30):
            obs, _ = sim.step(Control(float(rng.uniform(-0.2, 0.2)), 0.5))
            images.append(obs.image)
            states.append((sim.state.x, sim.state.y, sim.state.yaw, sim.state.v))
        return np.stack(images), np.array(states)

    a, b, c = episode(3), episode(3), episode(4)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0]) and not np.array_equal(a[1], c[1])


def test_routes_that_cannot_be_driven_are_refused(straight_road, town_graph):
    graph = straight_road["graph"]
    north = node_at(graph, 200.0, 120.0)  # the end of the side street, cut off below
    keep = [e for e in range(graph.num_edges) if north not in (graph.edges.u.iat[e], graph.edges.v.iat[e])]
    cut = type(graph)(graph.nodes, graph.edges.iloc[keep].reset_index(drop=True), [graph.geometry[e] for e in keep],
                      graph.crs, graph.virtual_node_spacing_m)
    with pytest.raises(InputError, match="no drivable route"):
        plan_route(cut, node_at(graph, 0.0, 60.0), north)  # a disconnected goal
    edges, froms = plan_route(graph, node_at(graph, 0.0, 60.0), node_at(graph, 400.0, 60.0))
    oneway = graph.edges.copy()
    oneway.loc[edges[0], "oneway"] = -1 if froms[0] == oneway.u.iat[edges[0]] else 1
    against = type(graph)(graph.nodes, oneway, graph.geometry, graph.crs, graph.virtual_node_spacing_m)
    with pytest.raises(InputError, match="one-way against the route"):
        check_route(against, edges, froms)
    with pytest.raises(InputError, match="no drivable route"):
        plan_route(against, node_at(graph, 0.0, 60.0), node_at(graph, 400.0, 60.0))
    edges, froms = plan_route(town_graph, node_at(town_graph, 0.0, 150.0), node_at(town_graph, 300.0, 150.0))
    with pytest.raises(InputError, match="not connected"):
        build_route(town_graph, edges[::-1], froms[::-1])


def test_bends_tighter_than_the_vehicle_turns_are_widened():
    """A 135-degree junction corner smoothed by 4 m still turns on ~1 m; widened, it turns on >= min_radius_m, and
    the lane away from the corner does not move."""
    west = np.column_stack([np.arange(-60.0, 0.0, DENSE_M), np.zeros(240)])
    t = np.arange(0.0, 60.0, DENSE_M)
    centre = np.vstack([west, np.column_stack([-t / np.sqrt(2), t / np.sqrt(2)])])
    smoothed = lane_polyline(centre, np.zeros(len(centre)), 4.0)
    assert lane_curvature(smoothed).max() > 1.0 / 3.86  # the vehicle's turning radius: no car follows this
    widened = widen_bends(smoothed, 5.0)
    assert lane_curvature(widened).max() <= 1.0 / 5.0
    moved = np.hypot(*(widened - smoothed).T)
    assert moved.max() > 2.0 and moved[:120].max() == 0.0 and moved[-120:].max() == 0.0
    fold = np.vstack([west, west[::-1]])  # out and back on the same line: no radius would do
    with pytest.raises(InputError, match="tighter than drive.lane.min_radius_m"):
        widen_bends(lane_polyline(fold, np.zeros(len(fold)), 4.0), 5.0)


def test_a_radius_the_vehicle_cannot_turn_and_a_lane_off_its_roads_are_refused(town_graph):
    edges, froms = plan_route(town_graph, node_at(town_graph, 0.0, 150.0), node_at(town_graph, 300.0, 150.0))
    conf = {"drive": drive_conf(lane={"min_radius_m": 3.0}), "place": make_config()["place"]}
    with pytest.raises(InputError, match="drive.lane.min_radius_m: 3.0 m is below the vehicle's turning radius"):
        route_of_edges(town_graph, edges, froms, conf)
    conf["drive"]["lane"]["min_radius_m"] = 5.0
    assert lane_curvature(route_of_edges(town_graph, edges, froms, conf).xy).max() <= 1.0 / 5.0
    (a, b) = TOWN_ROUTES["right"]
    edges, froms = plan_route(town_graph, node_at(town_graph, *a), node_at(town_graph, *b))
    assert not route_of_edges(town_graph, edges, froms, conf).off_corridor().any()
    conf["drive"]["lane"]["min_radius_m"] = 15.0  # a right turn on a 15 m radius cuts across the corner
    with pytest.raises(InputError, match="route: the lane leaves the route's roads at"):
        route_of_edges(town_graph, edges, froms, conf)


@pytest.mark.parametrize(("highway", "oneway", "right_of_centre_m"),
                         [("residential", "no", 7.0 / 4), ("service", "no", 0.0), ("residential", "yes", 0.0)])
def test_the_lane_keeps_right_of_a_drawn_centre_line_and_to_the_middle_of_other_roads(tmp_path, highway, oneway,
                                                                                        right_of_centre_m):
    """A two-way 7 m residential road has a dashed centre line in the images: keep to the middle of the right half.
    A two-way 4.5 m service road has none, nor has a one-way road: drive in the middle (what the camera can tell)."""
    osm = write_osm(tmp_path / "road.osm", {1: lonlat(0.0, 0.0), 2: lonlat(200.0, 0.0)},
                    [(10, [1, 2], {"highway": highway, "oneway": oneway})])
    graph, _ = build_road_graph(str(osm), [highway], 20.0)
    edges, froms = plan_route(graph, node_at(graph, 0.0, 0.0), node_at(graph, 200.0, 0.0))
    route = build_route(graph, edges, froms)
    centre_y = float(np.mean(graph.geometry[edges[0]][:, 1]))
    assert has_centre_line(road_width(highway), oneway == "no") == (right_of_centre_m > 0)
    assert centre_y - float(np.median(route.xy[:, 1])) == pytest.approx(right_of_centre_m, abs=0.05)  # east: right is south


@pytest.mark.parametrize(("tags", "width_m"), [({}, 7.0), ({"lanes": "4"}, 13.0), ({"lanes": "1"}, 4.0),
                                               ({"lanes": "4", "width": "9.5"}, 9.5), ({"width": "60"}, 7.0)])
def test_carriageways_are_as_wide_as_the_map_tags_them(tmp_path, tags, width_m):
    """The ``width`` tag, else ``lanes`` x 3.25 m (at least 4 m), else the class default: for the lane, the drivable area
    and the renderer alike (a 60 m ``width`` is not a carriageway)."""
    osm = write_osm(tmp_path / "road.osm", {1: lonlat(0.0, 0.0), 2: lonlat(200.0, 0.0)},
                    [(10, [1, 2], {"highway": "residential", **tags})])
    graph, _ = build_road_graph(str(osm), ["residential"], 20.0)
    assert carriageway_width("residential", float(graph.edges.lanes[0]), float(graph.edges.width_m[0])) == width_m
    assert [road.width for road in graph_roads(graph)] == [width_m]
    edges, froms = plan_route(graph, node_at(graph, 0.0, 0.0), node_at(graph, 200.0, 0.0))
    route = build_route(graph, edges, froms, margin_m=0.5)
    assert np.allclose(route.width, width_m)
    centre = graph.geometry[edges[0]].mean(axis=0)
    assert route.on_drivable(centre + [0.0, width_m / 2 + 0.25]) and not route.on_drivable(centre + [0.0, width_m / 2 + 1.0])
    offset = float(centre[1] - np.median(route.xy[:, 1]))  # two-way: a quarter of the carriageway right where marked
    assert offset == pytest.approx(width_m / 4 if has_centre_line(width_m, True) else 0.0, abs=0.05)


def test_a_lane_drawn_over_another_road_is_shared_and_random_routes_keep_clear_of_it(tmp_path):
    """A service road 3 m beside a residential street's centre line lies on its 7 m carriageway: the images show one
    surface, so its lane is shared (not within 15 m of the junctions at its ends); the street's own lane is not.
    Random routes (training, check) with more than drive.lane.max_shared_m shared are drawn again."""
    nodes = {1: lonlat(0.0, 0.0), 2: lonlat(20.0, 0.0), 3: lonlat(280.0, 0.0), 4: lonlat(300.0, 0.0),
             5: lonlat(40.0, 3.0), 6: lonlat(260.0, 3.0)}
    ways = [(10, [1, 2, 3, 4], {"highway": "residential"}), (11, [2, 5, 6, 3], {"highway": "service"})]
    graph, _ = build_road_graph(str(write_osm(tmp_path / "beside.osm", nodes, ways)), ["residential", "service"], 20.0)
    service = int(np.flatnonzero(graph.edges.highway == "service")[0])
    street = [e for e in range(graph.num_edges) if graph.edges.highway.iat[e] == "residential" and graph.edges.length_m.iat[e] > 200]
    beside = build_route(graph, [service], [node_at(graph, 20.0, 0.0)])
    along = build_route(graph, street, [node_at(graph, 20.0, 0.0)])
    assert 180.0 < beside.shared_m < 240.0 and along.shared_m == 0.0
    assert not beside.shared[beside.s < 10.0].any()  # at the junction the street covers it as it should
    assert beside.part(50.0, 100.0).shared_m == pytest.approx(100.0, abs=1.0)
    conf = make_config()
    drawn = [random_drive_route(graph, conf, 250.0, np.random.default_rng(k)) for k in range(12)]
    assert all(r is None or r.shared_m <= 10.0 for r in drawn) and any(r is not None for r in drawn)
    with pytest.raises(InputError, match=r"^drive\.lane\.max_shared_m: route 0 .*none of 20 draws"):
        training_route(0, conf, None, lambda rng: None)
    with pytest.raises(InputError, match=r"^drive\.demonstrations\.min_distance_m: route 0"):
        training_route(0, conf, beside.xy, lambda rng: beside)
    conf["drive"]["lane"]["max_shared_m"] = None
    assert any(r is not None and r.shared_m > 10.0 for r in (random_drive_route(graph, conf, 250.0, np.random.default_rng(k))
                                                             for k in range(12)))
