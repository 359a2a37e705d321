"""The one odometry noise model (topoloc.motion.noise) on a hand-made L-shaped drive."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

import topoloc

from topoloc.motion.noise import NOISE_KEYS, OdometryNoise, integrate_odometry
from topoloc.motion.poses import Odometry

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


def test_the_noisy_track_is_the_one_odometry_type_and_cuts_with_its_distances():
    track = integrate_odometry(XY, YAW, OdometryNoise(0.1, 0.0, 0.0, 0.0), np.random.default_rng(0))
    assert isinstance(track, Odometry) and len(track) == len(XY)
    later = track.cut(5)
    assert np.array_equal(later.xy, track.xy[5:]) and np.array_equal(later.yaw, track.yaw[5:])
    assert later.ds[0] == 0.0 and np.array_equal(later.ds[1:], track.ds[6:])
    assert later.driven_m[-1] == pytest.approx(track.ds[6:].sum())


def _noise_settings(node: object, where: str = "") -> dict[str, set[str]]:
    """Every object of the config schema that holds an odometry noise setting (a ``distance_noise`` key)."""
    found = {}
    if isinstance(node, dict):
        props = node.get("properties")
        if isinstance(props, dict) and "distance_noise" in props:
            found[where] = set(props)
        for key, value in node.items():
            found |= _noise_settings(value, f"{where}.{key}" if key != "properties" else where)
    return found


def test_every_noise_setting_of_the_config_has_the_one_set_of_keys():
    schema = yaml.safe_load((Path(topoloc.__file__).parent / "config.schema.yaml").read_text())
    settings = _noise_settings(schema)
    assert {".odometry.simulated.noise", ".dataset.simulated.noise", ".place.odometry_noise"} <= set(settings)
    assert all(keys == set(NOISE_KEYS) for keys in settings.values()), settings


def test_noisy_poses_keep_the_poses_without_noise_and_drift_by_the_set_level():
    from topoloc.motion.noise import noisy_poses
    from topoloc.motion.poses import planar_track, planar_yaw, poses_from_planar
    from topoloc.odometry.evaluate import evaluate

    # a 1.2 km drive of gentle curves, a frame per metre, the camera 1.7 m up and pitched 2 degrees
    s = np.arange(1200.0)
    yaw = 0.4 * np.sin(s / 150.0)
    xy = np.cumsum(np.column_stack([np.cos(yaw), np.sin(yaw)]), axis=0)
    pitch = np.radians(2.0)
    tilt = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    poses = poses_from_planar(xy, yaw)
    poses[:, :3, :3] = poses[:, :3, :3] @ tilt
    poses[:, 1, 3] = -1.7
    same = noisy_poses(poses, OdometryNoise(0.0, 0.0, 0.0, 0.0), np.random.default_rng(0))
    assert np.allclose(same, poses, atol=1e-9)
    drift = noisy_poses(poses, OdometryNoise(0.0, 0.0, 0.5, 0.0), np.random.default_rng(0))
    assert np.allclose(drift[:, 1, 3], -1.7) and np.allclose(drift[:, 1, :3], poses[:, 1, :3])  # height and tilt kept
    heading_error = np.degrees(np.unwrap(planar_yaw(drift)) - np.unwrap(planar_yaw(poses)))
    assert heading_error[-1] == pytest.approx(0.5 * 12, rel=0.01)  # 0.5 deg per 100 m over 1.2 km
    assert evaluate(poses, drift)["r_err_deg_per_100m"] == pytest.approx(0.5, rel=0.05)
    scaled = noisy_poses(poses, OdometryNoise(0.01, 0.0, 0.0, 0.0), np.random.default_rng(0))
    assert evaluate(poses, scaled)["t_err_pct"] == pytest.approx(1.0, rel=0.05)
    assert np.hypot(*(planar_track(scaled)[-1] - xy[0])) == pytest.approx(1.01 * np.hypot(*(xy[-1] - xy[0])), rel=1e-3)
    # seeded: the same seed, the same odometry
    level = OdometryNoise(0.01, 0.01, 0.5, 0.02)
    assert np.array_equal(noisy_poses(poses, level, np.random.default_rng(3)), noisy_poses(poses, level, np.random.default_rng(3)))
    assert not np.array_equal(noisy_poses(poses, level, np.random.default_rng(3)), noisy_poses(poses, level, np.random.default_rng(4)))
