"""The labels and scores of ``benchmarks.bench_lane_perception``: the lane's offset and heading read off a recorded
local path, the offset of the nearest road's centre line, and the scores of a perfect and of a constant answer."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_lane_perception import lane_pose, road_middle_offset, scores


def test_the_lane_pose_of_a_recorded_path():
    ahead = np.arange(1.0, 21.0)
    yaw = np.radians(10.0)  # a straight lane 1.2 m to the left, turned 10 deg left of the vehicle's heading
    path = np.column_stack([ahead * np.cos(yaw) - 1.2 * np.sin(yaw), 1.2 * np.cos(yaw) + ahead * np.sin(yaw)])
    right = path * np.array([1.0, -1.0])  # the mirror image: to the right, turned right
    pose = lane_pose(np.stack([path, right]).astype(np.float32))
    assert pose[0, 0] == pytest.approx(1.2 * np.cos(yaw), abs=1e-4)  # the y of the lane point at the vehicle
    assert pose[0, 1] == pytest.approx(yaw, abs=1e-4)
    assert np.allclose(pose[1], -pose[0], atol=1e-5)


def test_scores_tell_a_perfect_answer_from_a_constant_one():
    rng = np.random.default_rng(0)
    truth = np.column_stack([rng.normal(0, 1.0, 200), rng.normal(0, 0.1, 200)])
    perfect = scores(truth, truth)
    assert perfect["offset_corr"] == pytest.approx(1.0) and perfect["offset_rmse"] == pytest.approx(0.0)
    assert perfect["heading_rmse"] == pytest.approx(0.0) and perfect["heading_sd"] == pytest.approx(np.degrees(truth[:, 1].std()))
    constant = scores(np.column_stack([np.full(200, 0.01), np.zeros(200)]) + rng.normal(0, 1e-6, (200, 2)), truth)
    assert abs(constant["offset_corr"]) < 0.3
    assert constant["offset_rmse"] == pytest.approx(constant["offset_sd"], rel=0.05)


def test_the_road_middle_offset_is_signed_left_of_the_pose(straight_road):
    graph = straight_road["graph"]
    coords = graph.geometry[0]
    mid = coords[[0, -1]].mean(axis=0)  # the middle of the road's first edge: the side street is 30 m or more away
    heading = np.arctan2(*(coords[-1] - coords[0])[::-1])
    normal = np.array([-np.sin(heading), np.cos(heading)])  # left of the road's direction
    xy = np.stack([mid - 1.5 * normal, mid + 2.0 * normal])
    offset = road_middle_offset(graph, xy, np.full(2, heading))
    assert offset == pytest.approx([1.5, -2.0], abs=0.05)
    assert road_middle_offset(graph, xy[:1], np.array([heading + np.pi]))[0] == pytest.approx(-1.5, abs=0.05)  # facing back


def test_the_lane_offset_is_the_recorded_lateral_offset(straight_demos):
    """The benchmark reads the offset off the recorded path; the recorder's own ``lateral`` (+ right of the lane: the lane
    to the left) says the same, side views and noise injection included."""
    offset = lane_pose(straight_demos.path)[:, 0]
    assert np.abs(straight_demos.lateral).max() > 0.5  # the side views and the perturbations leave the lane
    assert np.abs(offset - straight_demos.lateral).max() < 0.1
