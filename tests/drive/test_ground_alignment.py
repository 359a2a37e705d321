"""Ground alignment (visual teach and repeat): the pose of a live view against a teach view of the town, under another
weather, with and without a prior; and the pose tracker that gives an aligned Topo-LP its path in the vehicle's
frame, along a drive of the town's right turn that starts off the lane."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.drive.conftest import lane_map, right_turn
from topoloc.drive.agents import LPAgent, TeachImages
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.ground_alignment import MATCH_GAIN, GroundAligner, PoseTracker, gradients
from topoloc.drive.local_path import PLANE_POINTS, chain_frame
from topoloc.drive.simulator import RUNNING, Control, Simulator
from topoloc.render.rig import StereoRig


@pytest.fixture(scope="module")
def turn(town, town_graph):
    """The right-turn route with the controller camera's shape (160 x 72: the rows down to 3.2 m of ground ahead)."""
    drive, conf, route, sim, _topo, lane_s = right_turn(town, town_graph)
    rig = dataclasses.replace(StereoRig.kitti(160, 48, 0.54, 1.65), height=72)
    sim = Simulator(route, sim.scene, rig, sim.spec, 100.0)
    return drive, conf, route, sim, lane_map(route), lane_s


def _pose(route, s: float, right_m: float = 0.0, yaw_deg: float = 0.0) -> tuple[np.ndarray, float]:
    k = route.index(s)
    yaw = float(route.yaw[k])
    return route.xy[k] + right_m * np.array([np.sin(yaw), -np.cos(yaw)]), yaw + np.radians(yaw_deg)


@pytest.mark.parametrize("right_m, yaw_deg, ahead_m", [(0.7, 4.0, 0.8), (-0.9, -5.0, -0.6)])
def test_a_view_beside_the_teach_view_is_placed_where_it_was_taken(turn, right_m, yaw_deg, ahead_m):
    _drive, _conf, route, sim, _topo, _lane_s = turn
    aligner = GroundAligner(sim.rig)
    for s in (25.0, 60.0):
        at, yaw = _pose(route, s)
        teach = aligner.reference(sim.renderer("clear_noon", 1).render(at, yaw, 0))
        live_at, live_yaw = _pose(route, s + ahead_m, right_m, yaw_deg)
        live = sim.renderer("rain", 2).render(live_at, live_yaw, 0)
        d = live_at - at
        truth = (np.cos(yaw) * d[0] + np.sin(yaw) * d[1], -np.sin(yaw) * d[0] + np.cos(yaw) * d[1], live_yaw - yaw)
        for prior in (None, (truth[0] + 0.3, truth[1] - 0.2, truth[2] + 0.02)):
            found = aligner.align(teach, live, prior)
            assert abs(found.left_m - truth[1]) < 0.25, (s, prior, found, truth)
            assert abs(np.degrees(found.yaw - truth[2])) < 1.5, (s, prior, found, truth)
            assert abs(found.forward_m - truth[0]) < 1.2, (s, prior, found, truth)  # along a straight road: weak
            assert found.score > 0.5
            assert aligner.align(teach, gradients(live), prior) == found  # told the image's gradients instead
            assert aligner.forward_peak(teach, gradients(live), found) == aligner.forward_peak(teach, live, found)


class _Recorder:
    """A Topo-LP stand-in trained on the aligned frame: it keeps the path points it is told, the expert drives."""

    def __init__(self, expert: Expert, sim: Simulator) -> None:
        self.hparams = {"path_frame": "aligned"}
        self.expert, self.sim, self.told, self.truth = expert, sim, [], []

    def act(self, image, speed, plane):
        self.told.append(plane[-1, : 2 * PLANE_POINTS].reshape(PLANE_POINTS, 2).copy())
        self.truth.append(self.sim.lateral)
        control = self.expert.control(self.sim.state)
        return control.steer, control.throttle


def test_an_aligned_topo_lp_is_told_the_path_where_the_vehicle_stands(turn):
    drive, _conf, route, sim, topo, lane_s = turn
    expert = Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    model = _Recorder(expert, sim)
    agent = LPAgent(model, topo, TeachImages(sim, topo, "clear_noon", 1, True))
    obs, status = sim.reset("night", 3, lateral_m=1.2, yaw_deg=-6.0), RUNNING
    expert.reset()
    while status == RUNNING:
        vertex = int(np.clip(np.searchsorted(lane_s, sim.s), 0, len(lane_s) - 1))
        obs, status = sim.step(agent.act(obs.image, obs.speed, vertex))
        if obs is None:
            break
    assert status == "success"
    # The path's point 1 m ahead is the lane beside the vehicle: left of it when the vehicle is right of the lane.
    told = np.array([p[0, 1] for p in model.told])
    truth = np.array(model.truth)
    assert np.median(np.abs(told - truth)) < 0.15 and np.percentile(np.abs(told - truth), 90) < 0.4
    assert told[0] > 0.8  # the start, 1.2 m right of the lane: the map's path is 1.2 m to the left


@pytest.mark.parametrize("relocalize_steps, found", [(2, True), (50, False)])
def test_the_tracker_searches_anew_after_its_matches_fail(turn, relocalize_steps, found):
    _drive, _conf, _route, sim, topo, _lane_s = turn
    vertex = 30
    at, yaw = chain_frame(topo.gt_xy, vertex)
    right = np.array([np.sin(yaw), -np.cos(yaw)])
    tracker = PoseTracker(GroundAligner(sim.rig), topo.xy, TeachImages(sim, topo, "clear_noon", 1, True), sim.spec,
                          relocalize_steps=relocalize_steps, align_every=1)
    render = sim.renderer("overcast", 4)
    start = tracker.update(render.render(at, yaw, 0), 0.0, vertex, None)
    assert np.hypot(*(start.centre(sim.spec) - at)) < 0.3
    blank = np.zeros((sim.rig.height, sim.rig.width, 3), np.uint8)
    for _ in range(2):  # nothing to match: the prior stands
        tracker.update(blank, 0.0, vertex, Control(0.0, 0.0))
        assert tracker.score < tracker.min_score
    # Then a view 1.2 m right of the teach drive, beyond the search around the prior (+-0.4 m).
    pose = tracker.update(render.render(at + 1.2 * right, yaw, 1), 0.0, vertex, Control(0.0, 0.0))
    error = float(np.hypot(*(pose.centre(sim.spec) - (at + 1.2 * right))))
    assert (error < 0.3) == found, error


def test_a_tracked_match_moves_the_pose_a_share_of_the_way_to_it(turn):
    _drive, _conf, _route, sim, topo, _lane_s = turn
    vertex = 30
    at, yaw = chain_frame(topo.gt_xy, vertex)
    right = np.array([np.sin(yaw), -np.cos(yaw)])
    tracker = PoseTracker(GroundAligner(sim.rig), topo.xy, TeachImages(sim, topo, "clear_noon", 1, True), sim.spec,
                          align_every=1)
    render = sim.renderer("overcast", 4)
    start = tracker.update(render.render(at, yaw, 0), 0.0, vertex, None)  # no prior: the match's pose itself
    aside = [float(np.dot(start.centre(sim.spec) - at, right))]
    for t in range(1, 16):  # the vehicle stands 0.35 m right of the teach drive (within the tracked search)
        pose = tracker.update(render.render(at + 0.35 * right, yaw, t), 0.0, vertex, Control(0.0, 0.0))
        aside.append(float(np.dot(pose.centre(sim.spec) - at, right)))
    assert abs(aside[0]) < 0.15
    first = (aside[1] - aside[0]) / (0.35 - aside[0])  # the share of the gap the first match closed
    assert 0.5 * MATCH_GAIN < first < 0.5, aside  # one match, 1-2 m off in a turn at night, would move it as little
    assert abs(aside[-1] - 0.35) < 0.08, aside  # a few matches, the whole of it
