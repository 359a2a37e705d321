"""The junction benchmark on a hand-made map whose junctions are known: a T, a crossroads, two side streets 15 m apart
(one junction of two nodes) and a fork, on one long road; and in closed loop on it, junctions taken by the expert and
the replay agent and missed by the trivial controllers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tests.conftest import make_config, write_osm
from tests.drive.conftest import BASELINES, ConstantSteer, drive_conf, lane_map, node_at, route_scene
from tests.render.conftest import lonlat
from topoloc.drive.agents import ExpertAgent, ReplayAgent
from topoloc.drive.drive_route import build_route
from topoloc.drive.episodes import run_episode, teach_controls
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.junctions import (FAILED, NOT_REACHED, TAKEN, classify_turn, junction_rates, junction_results,
                                     roundabout_ways, route_junctions)
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.repeat_routes import vertex_lane_s
from topoloc.drive.route_planning import plan_route
from topoloc.drive.simulator import Control, Simulator, VehicleSpec
from topoloc.graph.from_osm import build_road_graph
from topoloc.graph.road_graph import RoadGraph
from topoloc.render.rig import StereoRig

#: Ways of the junction map: (id, points in metres, extra tags).
JUNCTION_WAYS = [
    (10, [(0, 0), (150, 0), (300, 0), (450, 0), (465, 0), (600, 0)], {}),  # the main road, west to east
    (11, [(150, 0), (150, 80)], {}),  # a T: a side street north
    (12, [(300, -80), (300, 0), (300, 80)], {}),  # a crossroads
    (13, [(450, 0), (450, 80)], {}),  # a staggered crossing: north at 450 m ...
    (14, [(465, 0), (465, -80)], {"junction": "roundabout"}),  # ... and south 15 m on (one way: tagged for a test)
    (15, [(600, 0), (700, 60)], {}),  # a fork: left ...
    (16, [(600, 0), (700, -60)], {}),  # ... and right
]


@pytest.fixture(scope="module")
def junction_map(tmp_path_factory) -> dict:
    """The OSM file and road graph of :data:`JUNCTION_WAYS` (two-way residential roads)."""
    tmp = tmp_path_factory.mktemp("junctions")
    ids: dict[tuple[int, int], int] = {}
    ways = []
    for way, points, tags in JUNCTION_WAYS:
        refs = [ids.setdefault(p, 100 + len(ids)) for p in points]
        ways.append((way, refs, {"highway": "residential", **tags}))
    osm = write_osm(tmp / "junctions.osm", {n: lonlat(*p) for p, n in ids.items()}, ways)
    graph, _ = build_road_graph(str(osm), ["residential"], 20.0)
    return {"osm": osm, "graph": graph}


def _route(graph: RoadGraph, start: tuple[float, float], goal: tuple[float, float]):
    edges, froms = plan_route(graph, _node(graph, *start), _node(graph, *goal))
    return build_route(graph, edges, froms)


def _node(graph: RoadGraph, x: float, y: float) -> int:
    """The node at (x, y) metres of the map (the map's south-west corner is (0, -80))."""
    return node_at(graph, x, y + 80.0)


def test_turn_classes():
    assert [classify_turn(a) for a in (5, -15, 35, -50, 90, -95, 140, -150, 175, -170)] == [
        "straight", "straight", "slight left", "slight right", "left", "right", "sharp left", "sharp right",
        "U-turn", "U-turn"]


def test_a_route_through_every_kind_counts_each_junction_once(junction_map):
    graph = junction_map["graph"]
    route = _route(graph, (0, 0), (700, 60))
    found = route_junctions(graph, route)
    assert [j.kind for j in found] == ["T", "cross", "cluster", "fork"]
    assert [len(j.nodes) for j in found] == [1, 1, 2, 1]
    assert [j.turn for j in found] == ["straight", "straight", "straight", "slight left"]
    assert found[3].angle_deg == pytest.approx(31.0, abs=6.0)
    assert [j.exits for j in found] == [2, 3, 3, 2]
    assert [j.entry_s for j in found] == pytest.approx([150, 300, 450, 600], abs=3.0)
    assert found[2].exit_s == pytest.approx(465, abs=3.0)
    assert [j.gap_m for j in found] == pytest.approx([150, 150, 150, 135], abs=4.0)
    # a tighter cluster distance splits the staggered crossing into two T junctions
    assert [j.kind for j in route_junctions(graph, route, cluster_m=10.0)] == ["T", "cross", "T", "T", "fork"]
    # a road of a roundabout makes its junction a roundabout
    assert roundabout_ways(str(junction_map["osm"])) == {14} and roundabout_ways(None) == set()
    assert [j.kind for j in route_junctions(graph, route, {14})] == ["T", "cross", "roundabout", "fork"]


def test_turns_keep_their_side(junction_map):
    graph = junction_map["graph"]
    right = route_junctions(graph, _route(graph, (0, 0), (300, -80)))
    assert [(j.kind, j.turn) for j in right] == [("T", "straight"), ("cross", "right")]
    assert right[1].angle_deg == pytest.approx(-90.0, abs=10.0)
    left = route_junctions(graph, _route(graph, (300, -80), (150, 80)))
    assert [(j.kind, j.turn) for j in left] == [("cross", "left"), ("T", "right")]  # west at the cross, north at the T


def test_drive_results_blame_the_junction_where_the_drive_ended(junction_map):
    graph = junction_map["graph"]
    found = route_junctions(graph, _route(graph, (0, 0), (700, 60)))
    s = np.arange(0.0, 310.0, 1.0)  # ended 10 m past the crossroads (on a wrong road)
    rows = junction_results(found, s, np.full(len(s), 5.0), "wrong_road")
    assert [r["result"] for r in rows] == [TAKEN, FAILED, NOT_REACHED, NOT_REACHED]
    assert rows[1]["outcome"] == "wrong_road" and rows[0]["outcome"] == ""
    assert rows[0]["entry_speed_mps"] == 5.0 and np.isnan(rows[2]["entry_speed_mps"])
    done = junction_results(found, np.arange(0.0, 700.0), np.ones(700), "success")
    assert all(r["result"] == TAKEN for r in done)
    table = pd.DataFrame([{**r, "agent": "a"} for r in rows] + [{**r, "agent": "b"} for r in done])
    rates = junction_rates(table, "kind", ("T", "cross", "fork", "roundabout", "cluster"))
    assert rates["rate"].loc["a"].tolist()[:2] == [1.0, 0.0] and rates["rate"].loc["b"].tolist()[:4] == [1.0, 1.0, 1.0, 1.0]
    assert rates["reached"].loc["a", "T"] == 1


#: Routes of the closed-loop junction test (start, goal in metres of the map): every kind and turn side, few straights.
DRIVE_ROUTES = [((0, 0), (300, -80)),  # straight at the T, right at the cross
                ((300, -80), (150, 80)),  # left at the cross, right at the T
                ((150, 80), (300, 80)),  # left at the T, left at the cross
                ((450, 80), (700, 60)),  # left through the staggered crossing (one junction), left at the fork
                ((465, 0), (700, -60))]  # right at the fork (the cluster's last node is the start)


class _Constant:
    """A baseline at the wheel of a repeat drive: fixed steering, the expert's cruise speed."""

    def __init__(self, steer: float, drive: dict) -> None:
        self.base = ConstantSteer(steer, drive)

    def act(self, image, speed, vertex) -> Control:
        return Control(*self.base.act(image, speed, None))


@pytest.fixture(scope="module")
def junction_drives(junction_map) -> list[tuple]:
    """Per route of :data:`DRIVE_ROUTES`: the stage config, the route, its simulator (64 x 48 camera), lane map, its
    vertices' arc lengths, the expert and its junctions."""
    drive = drive_conf(follow={"start_lateral_m": 0.0, "start_yaw_deg": 0.0})
    conf = {"drive": drive, "place": make_config()["place"]}
    graph = junction_map["graph"]
    out = []
    for start, goal in DRIVE_ROUTES:
        route = _route(graph, start, goal)
        sim = Simulator(route, route_scene(junction_map["osm"], graph, route), StereoRig.kitti(64, 48, 0.54, 1.65),
                        VehicleSpec.from_conf(drive), 60.0)
        topo = lane_map(route)
        lane_s = vertex_lane_s(route, topo)
        expert = Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
        out.append((conf, route, sim, topo, lane_s, expert, route_junctions(graph, route)))
    return out


def test_the_junction_routes_cover_every_kind_and_side(junction_drives):
    found = [(j.kind, j.turn) for *_, junctions in junction_drives for j in junctions]
    assert found == [("T", "straight"), ("cross", "right"), ("cross", "left"), ("T", "right"), ("T", "left"),
                     ("cross", "left"), ("cluster", "left"), ("fork", "slight left"), ("fork", "slight right")]


@pytest.mark.parametrize("driver", ["expert", "replay", *BASELINES])
def test_closed_loop_junctions_are_taken_by_a_driver_and_missed_by_a_trivial_one(junction_drives, driver):
    rows = []
    for conf, route, sim, topo, lane_s, expert, junctions in junction_drives:
        if driver == "expert":
            agent = ExpertAgent(expert, sim)
        elif driver == "replay":
            steer, speed = teach_controls(sim, expert, "clear_noon", 0, lane_s)
            agent = ReplayAgent(steer, speed, float(conf["drive"]["expert"]["speed_gain"]))
        else:
            agent = _Constant(BASELINES[driver], conf["drive"])
        episode = run_episode(sim, agent, GroundTruth(lane_s), topo, "clear_noon", 3, conf)
        rows += junction_results(junctions, episode.s, episode.speed, episode.outcome)
    taken = np.mean([r["result"] == TAKEN for r in rows])  # of every junction on the routes, reached or not
    if driver in BASELINES:
        assert taken <= 0.3, f"{driver} took {taken:.2f} of the junctions"
    else:
        assert taken >= 0.95, f"{driver} took {taken:.2f} of the junctions"
        assert all(np.isfinite(r["entry_speed_mps"]) and 1.0 < r["entry_speed_mps"] < 8.0 for r in rows)
