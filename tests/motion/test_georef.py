"""Georeferencing by an origin and by a rigid fit to GPS."""

import numpy as np
import pytest

from topoloc.motion.georef import fit_rigid, from_origin, grid_heading_deg, to_map
from topoloc.motion.poses import planar_track, planar_yaw, read_gps, read_poses


def test_origin_puts_forward_along_heading():
    geo = from_origin(np.array([100.0, 200.0]), 90.0, np.zeros(2), np.pi / 2)  # heading east
    assert np.allclose(geo.apply(np.array([[0.0, 0.0], [0.0, 10.0], [1.0, 0.0]])),
                       [[100, 200], [110, 200], [100, 199]])


def test_fit_recovers_rotation_and_translation():
    rng = np.random.default_rng(1)
    local = rng.normal(size=(50, 2)) * 100
    theta = np.radians(-40.0)
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    geo = fit_rigid(local, local @ rot.T + [5.0, -3.0])
    assert geo.theta == pytest.approx(theta)
    assert np.allclose(geo.t, [5.0, -3.0])
    assert geo.rms_m < 1e-9


@pytest.mark.kitti
def test_kitti_gps_fit_heading(kitti00):
    poses = read_poses(kitti00 / "poses" / "00_gt.txt")
    gps = read_gps(kitti00 / "gps" / "00_latlon.csv", len(poses))
    crs = "EPSG:32632"
    geo = fit_rigid(planar_track(poses), to_map(crs, gps[:, 0], gps[:, 1]))
    assert geo.rms_m < 1.5
    # README: 30.55 deg clockwise from true north; UTM grid north differs by the meridian convergence.
    assert geo.heading_deg(planar_yaw(poses)[0]) == pytest.approx(grid_heading_deg(crs, *gps[0], 30.55), abs=0.3)
