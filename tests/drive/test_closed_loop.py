"""Closed-loop teach and repeat on the town: the replay baseline with ground-truth localization, and a map of
another route refused."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import make_config
from tests.drive.conftest import drive_conf, lane_map, right_turn, route_scene, town_route
from topoloc.drive.agents import ReplayAgent
from topoloc.drive.episodes import run_episode, speed_limit_ahead, teach_controls
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.repeat_routes import intersections, repeat_routes, route_starts, vertex_lane_s
from topoloc.drive.simulator import Control, Simulator, VehicleSpec
from topoloc.errors import InputError
from topoloc.place.topometric_map import TopometricMap
from topoloc.render.rig import StereoRig


def test_replay_with_ground_truth_follows_the_teach_drive(town, town_graph):
    drive, conf, route, sim, topo, lane_s = right_turn(town, town_graph)
    assert np.allclose(lane_s[:-5], np.arange(len(lane_s) - 5), atol=0.2)
    expert = Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    steer, speed = teach_controls(sim, expert, "clear_noon", 0, lane_s)
    assert steer.min() < -0.3 and speed.max() > 5.0  # the right turn and the cruise speed were recorded
    episode = run_episode(sim, ReplayAgent(steer, speed, 0.5), GroundTruth(lane_s), topo, "night", 1, conf, 4)
    assert episode.outcome == "success"
    assert np.median(episode.loc_error_m) < 1.0 and len(episode.frames) == 4
    other = town_route(town_graph, "left", drive)
    with pytest.raises(InputError, match="do not follow the teach route"):
        vertex_lane_s(other, topo)
    # a map of a teach route that comes back past the driven part (KITTI 00's loops): the later vertices are not
    # projected onto the cut lane, where they would read as 5 m off it
    there = lane_map(route)
    back = np.repeat(there.gt_xy[::-1], 2, axis=0) + np.array([0.0, 5.0])  # slowly: more vertices than the way out
    looped = TopometricMap(*(np.concatenate([a, a, a]) for a in (there.embedding, there.embedding)),
                           np.concatenate([there.xy, back]), np.concatenate([there.command] * 3),
                           np.concatenate([there.gt_xy, back]), "clear_noon")
    short = route.cut(60.0)
    lane_s = vertex_lane_s(short, looped)
    assert np.allclose(lane_s[:55], np.arange(55), atol=0.2) and np.all(lane_s[80:] == short.length_m)


class FullThrottle(ReplayAgent):
    """The teach drive's steering at full throttle: an agent that never slows for a turn."""

    def act(self, image, speed, vertex):
        return Control(float(self.steer[vertex]), 1.0)


def test_speed_limit_ahead_is_the_slowest_teach_speed_in_reach():
    speed, lane_s = np.array([6.0, 6.0, 6.0, 3.0, 6.0]), np.array([0.0, 5.0, 10.0, 15.0, 20.0])
    assert speed_limit_ahead(speed, lane_s, 10.0).tolist() == [6.0, 3.0, 3.0, 3.0, 6.0]
    assert speed_limit_ahead(speed, lane_s, 0.0).tolist() == speed.tolist()


def test_the_map_speed_limit_holds_an_agent_that_never_slows_to_the_teach_speed(town, town_graph):
    drive, conf, route, sim, topo, lane_s = right_turn(town, town_graph)
    steer, speed = teach_controls(sim, Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"])),
                                  "clear_noon", 0, lane_s)
    limit = speed_limit_ahead(speed, lane_s, 10.0)
    reckless = FullThrottle(steer, speed, 0.5)
    hz, excess = sim.spec.control_hz, []
    for speed_limit in (None, limit):
        episode = run_episode(sim, reckless, GroundTruth(lane_s), topo, "clear_noon", 1, conf, speed_limit=speed_limit)
        assert episode.outcome == "success"
        v = np.hypot(*np.diff(episode.xy, axis=0).T) * hz  # speed per step from the driven path
        at = np.searchsorted(lane_s, np.concatenate([[0.0], np.cumsum(v[:-1] / hz)])).clip(0, len(lane_s) - 1)
        excess.append(float((v - limit[at]).max()))
    assert limit.min() < 4.0  # the teach drive slowed for the right turn
    assert excess[0] > 5.0 and excess[1] < 1.5  # at most the throttle's lag over the limit


def test_repeat_routes_split_the_teach_route_each_with_the_map_of_its_stretch(town, town_graph):
    drive = drive_conf(follow={"start_lateral_m": 0.0, "start_yaw_deg": 0.0})
    conf = {"drive": drive, "place": make_config()["place"]}
    teach = town_route(town_graph, "right", drive).cut(175.0)
    topo = lane_map(teach)
    parts = repeat_routes(teach, topo, 60.0, 3)
    assert [p.start_m for p in parts] == pytest.approx([0.0, (teach.length_m - 60.0) / 2, teach.length_m - 60.0], abs=0.3)
    assert [p.start_m for p in parts] == [teach.s[np.searchsorted(teach.s, p.start_m)] for p in parts]  # lane samples
    assert np.allclose(parts[-1].topo.gt_xy[-1], topo.gt_xy[-1])  # the last route keeps the goal's vertex
    for part in parts:
        route = part.route
        assert route.s[0] == 0.0 and route.length_m == pytest.approx(60.0, abs=0.3)
        assert np.allclose(route.xy[0], teach.point(part.start_m), atol=0.3)
        assert np.allclose(part.topo.gt_xy[0], route.xy[0], atol=1.0)  # the map starts where the route does
        assert part.lane_s[0] < 1.0 and part.lane_s[-1] <= route.length_m + 0.5 and len(part.topo) == len(part.lane_s)
        assert np.allclose(part.lane_s, vertex_lane_s(route, part.topo), atol=0.3)
    assert set(parts[0].route.command.tolist()) == {0} and 2 in parts[2].route.command  # the right turn is on the last
    # the corridor of a part is its own roads: the road the teach route turns into after the first part is a wrong road
    south = teach.point(teach.length_m - 5.0)
    assert teach.on_corridor(south) and not parts[0].route.on_corridor(south) and parts[2].route.on_corridor(south)
    assert all(parts[0].route.on_corridor(xy) for xy in parts[0].route.xy[::20])
    last = parts[2]
    sim = Simulator(last.route, route_scene(town["osm"], town_graph, last.route), StereoRig.kitti(64, 48, 0.54, 1.65),
                    VehicleSpec.from_conf(drive), 100.0)
    expert = Expert(last.route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    steer, speed = teach_controls(sim, expert, "clear_noon", 0, last.lane_s)
    episode = run_episode(sim, ReplayAgent(steer, speed, 0.5), GroundTruth(last.lane_s), last.topo, "rain", 2, conf)
    assert episode.outcome == "success" and np.median(episode.loc_error_m) < 1.0
    assert route_starts(175.0, None, 1) == [0.0] and route_starts(175.0, 60.0, 1) == [0.0]
    for length in (None, 175.0, 200.0):  # several routes that would all be the whole teach route
        with pytest.raises(InputError, match="drive.follow.routes"):
            route_starts(175.0, length, 2)


def test_intersections_count_each_stretch_of_a_turn_command():
    assert intersections([0, 0, 1, 1, 0, 2, 2, 0, 1]) == 3  # left, right, left again: three, not two command types
    assert intersections([3, 3, 1, 1]) == 2 and intersections([0, 0]) == 0 and intersections([]) == 0
