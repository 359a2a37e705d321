"""KITTI file readers: values, and one-line errors that name file and line."""

import numpy as np
import pytest

from topoloc.errors import InputError
from topoloc.motion.poses import (
    planar_track,
    planar_yaw,
    poses_from_planar,
    read_calib,
    read_gps,
    read_poses,
    read_times,
    write_poses,
)

IDENTITY = "1 0 0 0 0 1 0 0 0 0 1 0\n"


def test_round_trip(tmp_path):
    track = np.array([[0.0, 0.0], [0.5, 1.0], [1.5, 2.0]])
    yaw = np.radians([90.0, 80.0, 60.0])
    poses = poses_from_planar(track, yaw)
    write_poses(tmp_path / "p.txt", poses)
    back = read_poses(tmp_path / "p.txt")
    assert np.allclose(planar_track(back), track, atol=1e-5)
    assert np.allclose(planar_yaw(back), yaw, atol=1e-5)
    assert np.allclose(np.linalg.det(back[:, :3, :3]), 1.0, atol=1e-5)


def test_identity_looks_along_z():
    assert planar_yaw(poses_from_planar(np.zeros((1, 2)), np.array([np.pi / 2])))[0] == pytest.approx(np.pi / 2)
    assert np.allclose(poses_from_planar(np.zeros((1, 2)), np.array([np.pi / 2]))[0], np.eye(4))


def test_malformed_poses_line_names_file_and_line(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text(IDENTITY + "1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(InputError, match=r"bad.txt:2: a poses line needs 12 numbers \(3x4 matrix\), got 11$"):
        read_poses(path)
    path.write_text(IDENTITY * 2 + "1 0 0 x 0 1 0 0 0 0 1 0\n")
    with pytest.raises(InputError, match=r"bad.txt:3: not a number"):
        read_poses(path)


def test_nan_in_inputs_is_named_as_such(tmp_path):
    path = tmp_path / "nan.txt"
    path.write_text(IDENTITY + "1 0 0 nan 0 1 0 0 0 0 1 inf\n")
    with pytest.raises(InputError, match=r"nan.txt:2: a poses line needs finite numbers, got nan, inf \(value 4 of 12\)$"):
        read_poses(path)
    (tmp_path / "times.txt").write_text("0.0\nnan\n")
    with pytest.raises(InputError, match=r"times.txt:2: a timestamp needs a finite number, got nan$"):
        read_times(tmp_path / "times.txt", 2)
    (tmp_path / "gps.csv").write_text("frame,lat,lon\n0,NaN,8.3\n")
    with pytest.raises(InputError, match=r"gps.csv:2: lat/lon need finite numbers, got NaN, 8.3$"):
        read_gps(tmp_path / "gps.csv", 1)


def test_gps_shorter_than_poses(tmp_path):
    path = tmp_path / "gps.csv"
    path.write_text("# comment\nframe,lat,lon,alt\n0,48.9,8.3,100\n1,48.9,8.3,100\n")
    assert read_gps(path, 2).shape == (2, 2)
    with pytest.raises(InputError, match=r"gps.csv: GPS file covers 2 of the 3 pose frames"):
        read_gps(path, 3)


def test_times_count(tmp_path):
    path = tmp_path / "times.txt"
    path.write_text("0.0\n0.1\n")
    assert read_times(path, 2).tolist() == [0.0, 0.1]
    with pytest.raises(InputError, match="2 timestamps for 3 poses"):
        read_times(path, 3)


def test_missing_calib(tmp_path):
    with pytest.raises(InputError, match="calib.txt not found"):
        read_calib(tmp_path / "calib.txt")


def test_real_calib(kitti00):
    k, baseline = read_calib(kitti00 / "images" / "calib.txt")
    assert k[0, 0] == pytest.approx(718.856)
    assert baseline == pytest.approx(0.537, abs=1e-3)
