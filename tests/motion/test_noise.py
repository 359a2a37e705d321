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
