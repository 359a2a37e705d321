"""KITTI odometry errors and ATE on trajectories with known errors."""

import numpy as np
import pytest

from topoloc.motion.poses import poses_from_planar, read_poses
from topoloc.odometry.evaluate import evaluate


def straight(n, step):
    return poses_from_planar(np.column_stack([np.zeros(n), step * np.arange(n)]), np.full(n, np.pi / 2))


def test_scale_error_on_straight_line():
    result = evaluate(straight(1001, 1.0), straight(1001, 1.03))
    assert result["t_err_pct"] == pytest.approx(3.0, rel=1e-6)
    assert result["r_err_deg_per_100m"] == pytest.approx(0.0, abs=1e-6)
    assert result["kitti_subsequences"] == 448  # sum over lengths L = 100..800 of the starts 0, 10, .., 1000 - L


def test_heading_drift_gives_rotational_error():
    n = 1001
    gt = straight(n, 1.0)
    yaw = np.pi / 2 + np.radians(1.0) / 100.0 * np.arange(n)  # 1 deg per 100 m
    steps = np.column_stack([np.cos(yaw), np.sin(yaw)])
    est = poses_from_planar(np.vstack([[0, 0], np.cumsum(steps[1:], axis=0)]), yaw)
    assert evaluate(gt, est)["r_err_deg_per_100m"] == pytest.approx(1.0, rel=1e-3)


@pytest.mark.kitti
def test_orbslam2_errors(kitti00):
    gt = read_poses(kitti00 / "poses" / "00_gt.txt")
    est = read_poses(kitti00 / "poses" / "00_orbslam2.txt")
    result = evaluate(gt, est)
    assert result["ate_m"] == pytest.approx(1.3, abs=0.1)  # README: about 1.3 m after a rigid fit
    assert 0.3 < result["t_err_pct"] < 1.5
