"""The one odometry noise model (topoloc.motion.noise) on a hand-made L-shaped drive."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.motion.noise import OdometryNoise, integrate_odometry

# 20 m east, then 10 m north, a frame per metre; heading = direction of travel.
XY = np.concatenate([np.column_stack([np.arange(21.0), np.zeros(21)]), np.column_stack([np.full(10, 20.0), np.arange(1.0, 11.0)])])
YAW = np.concatenate([np.zeros(21), np.full(10, np.pi / 2)])


def test_without_noise_the_odometry_is_the_truth_from_the_origin():
    track = integrate_odometry(XY, YAW, OdometryNoise(0.0, 0.0, 0.0, 0.0), np.random.default_rng(0))
    assert np.allclose(track.xy, XY - XY[0])
    assert np.allclose(track.yaw, YAW)
    assert track.ds[0] == 0.0 and np.allclose(track.ds[1:], 1.0)


def test_scale_error_and_drift_are_deterministic():
    track = integrate_odometry(XY, YAW, OdometryNoise(0.1, 0.0, 10.0, 0.0), np.random.default_rng(0))
    assert track.ds[1:].sum() == pytest.approx(30 * 1.1)
    assert track.yaw[-1] - YAW[-1] == pytest.approx(np.radians(10.0) * 30 / 100)


def test_backward_steps_move_against_the_heading_and_standstill_gets_no_heading_noise():
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    yaw = np.zeros(4)
    track = integrate_odometry(xy, yaw, OdometryNoise(0.0, 0.0, 0.0, 5.0), np.random.default_rng(1), sign=[1.0, 1.0, -1.0])
    assert track.ds.tolist() == [0.0, 1.0, 0.0, -1.0]
    assert track.yaw[2] == track.yaw[1]  # the standing frame
    assert track.xy[3, 0] < track.xy[2, 0]


def test_from_dict_takes_the_config_keys():
    keys = {"scale_error": 0.02, "distance_noise": 0.01, "heading_drift_deg_per_100m": 0.5, "heading_noise_deg": 0.05}
    assert OdometryNoise.from_dict(keys) == OdometryNoise(0.02, 0.01, 0.5, 0.05)
    with pytest.raises(KeyError):
        OdometryNoise.from_dict({"scale_error": 0.02})
