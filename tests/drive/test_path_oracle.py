"""The path oracle of ``benchmarks.bench_lane_offset`` (Topo-LP's ceiling: the expert's pure pursuit on the local path
Topo-LP is told, with the vehicle's pose off it known): it steers as the expert on the expert's own lane, drives the
town's right turn from a map whose path-integrated chain lies in another frame, and leaves the road where the teach
drive it places the path on lies beside the road, so what it follows is the map, not the lane."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_lane_offset import PathOracle, _pursuit
from tests.drive.conftest import right_turn
from topoloc.drive.episodes import run_episode
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.simulator import VehicleState
from topoloc.place.topometric_map import TopometricMap


def test_pursuit_on_the_lane_is_the_experts_steering(town, town_graph):
    drive, _conf, route, sim, _topo, _lane_s = right_turn(town, town_graph)
    settings = ExpertSettings.from_conf(drive["expert"])
    lane = np.stack([route.point(s) for s in np.arange(0.0, route.length_m, 0.25)])
    bend = float(route.s[np.argmax(np.abs(np.gradient(np.unwrap(route.yaw))))])  # in the right turn
    steers = []
    for s, off, yaw, v in [(20.0, 0.8, 0.1, 5.0), (60.0, -0.5, -0.05, 6.0), (bend, 0.0, 0.0, 3.0), (bend + 3.0, 0.3, 0.0, 4.0)]:
        expert = Expert(route, sim.spec, settings)
        expert.s_rear = s  # it projects the rear axle near its last progress
        k = route.index(s)
        xy = route.xy[k] + off * np.array([np.sin(route.yaw[k]), -np.cos(route.yaw[k])])
        state = VehicleState(float(xy[0]), float(xy[1]), float(route.yaw[k] + yaw), v)
        ours, theirs = _pursuit(lane, state, sim.spec, settings), expert.control(state).steer
        assert abs(ours - theirs) < 0.03, (s, ours, theirs)
        steers.append(theirs)
    assert min(steers) < -0.25 and max(steers) > 0.15  # the states make the expert steer, right in the turn


def _moved(topo: TopometricMap, xy: np.ndarray | None = None, gt_xy: np.ndarray | None = None) -> TopometricMap:
    return TopometricMap(topo.embedding, topo.descriptor, topo.xy if xy is None else xy, topo.command,
                         topo.gt_xy if gt_xy is None else gt_xy, topo.condition)


def test_the_oracle_follows_the_maps_path_in_any_frame(town, town_graph):
    drive, conf, route, sim, topo, lane_s = right_turn(town, town_graph)
    expert = Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    turn = np.radians(40.0)  # the path-integrated chain in a frame turned by 40 deg and 300 m away
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    other_frame = _moved(topo, topo.xy @ rot.T + np.array([300.0, -120.0]))
    beside = _moved(topo, gt_xy=topo.gt_xy + np.array([0.0, 6.0]))  # a teach drive 6 m north of the road driven
    outcomes = {}
    for name, mapped in (("other_frame", other_frame), ("beside", beside)):
        episode = run_episode(sim, PathOracle(mapped, sim, expert), GroundTruth(lane_s), mapped, "overcast", 0, conf)
        outcomes[name] = episode.outcome
    assert outcomes["other_frame"] == "success"
    assert outcomes["beside"] in ("off_road", "wrong_road")
