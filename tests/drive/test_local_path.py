"""Topo-LP's local path: the map's path and the demonstrations' lane path give the same image for the same road,
the vehicle's own offset is not in it, turns bend it the right way, and the training noise moves it."""

from __future__ import annotations

import numpy as np

from topoloc.drive.local_path import (
    PATH_PX,
    PLANE_POINTS,
    aligned_path,
    chain_frame,
    lane_frame_path,
    map_path,
    path_plane,
    raster,
    vehicle_frame_path,
)


def _arc(radius: float, n: int = 40) -> np.ndarray:
    """A left-hand quarter circle after 10 m straight, every metre, starting at the origin heading east."""
    straight = np.column_stack([np.arange(0.0, 10.0), np.zeros(10)])
    t = np.arange(n) / radius
    curve = np.column_stack([10.0 + radius * np.sin(t), radius * (1.0 - np.cos(t))])
    return np.vstack([straight, curve])


def _vehicle_frame(points: np.ndarray, origin: np.ndarray, yaw: float) -> np.ndarray:
    d = points - origin
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c]).astype(np.float32)


def test_straight_road_is_a_vertical_line_in_the_middle():
    image = raster(map_path(np.column_stack([np.arange(0.0, 50.0), np.zeros(50)]), 0))
    cols = np.flatnonzero(image.max(axis=0) > 0)
    assert set(cols) <= set(range(PATH_PX // 2 - 2, PATH_PX // 2 + 2))
    assert image[:, PATH_PX // 2 - 1: PATH_PX // 2 + 1].max(axis=1).min() > 100  # every row, ahead to 20 m


def test_a_left_turn_bends_left_and_the_vehicle_offset_is_left_out():
    road = _arc(12.0)
    left = raster(map_path(road, 0))
    right = raster(map_path(road * [1, -1], 0))
    top = lambda im: np.flatnonzero(im[: PATH_PX // 3].max(axis=0) > 0)
    assert top(left).min() < PATH_PX // 2 - 6 and top(left).max() < PATH_PX // 2
    assert top(right).max() > PATH_PX // 2 + 5 and top(right).min() > PATH_PX // 2 - 1
    # The demonstrations record the lane ahead in the vehicle frame; off the lane by 1 m and 8 degrees, the
    # local path in the lane's frame is the map's.
    vehicle = _vehicle_frame(road[1:21], np.array([0.0, -1.0]), np.radians(8.0))
    np.testing.assert_allclose(lane_frame_path(vehicle), map_path(road, 0), atol=0.05)  # chords of 1 m arcs
    assert np.abs(raster(lane_frame_path(vehicle)).astype(int) - left).mean() < 2.0


def test_training_noise_moves_the_path():
    road = _arc(12.0)
    vehicle = _vehicle_frame(road[1:21], np.zeros(2), 0.0)
    ahead = lane_frame_path(vehicle, shift_m=4.0)
    np.testing.assert_allclose(ahead[:17], map_path(road, 4)[:17], atol=0.05)  # beyond the 20 m recorded: straight on
    turned = lane_frame_path(vehicle, yaw_rad=np.radians(5.0))  # the frame turned left: the path seen 5 deg right
    assert np.isclose(np.degrees(np.arctan2(turned[2, 1], turned[2, 0])), -5.0, atol=1e-6)


def test_the_plane_holds_the_image_and_the_points_ahead():
    points = map_path(_arc(8.0), 5)
    plane = path_plane(points)
    assert plane.shape == (PATH_PX + 1, PATH_PX) and plane.dtype == np.float32
    np.testing.assert_array_equal(plane[:PATH_PX], raster(points))
    np.testing.assert_allclose(plane[PATH_PX].reshape(-1, 2), points[1:PLANE_POINTS + 1], atol=1e-5)
    assert plane[PATH_PX, 2 * 15 + 1] > 3.0  # 16 m ahead, 11 m into the left bend of 8 m radius


def test_the_aligned_path_is_the_maps_path_seen_from_where_the_vehicle_stands():
    road = _arc(12.0)
    origin, yaw = chain_frame(road, 3)
    np.testing.assert_allclose(aligned_path(road, 3, origin, yaw), map_path(road, 3), atol=1e-9)
    # 1.5 m right of the chain and turned 10 deg left: the path starts 1.5 m to the left and runs off to the right.
    right = np.array([np.sin(yaw), -np.cos(yaw)])
    seen = aligned_path(road, 3, origin + 1.5 * right, yaw + np.radians(10.0))
    assert abs(seen[0, 0]) < 0.3 and 1.4 < seen[0, 1] < 1.6
    assert seen[5, 1] < seen[0, 1] - 0.5
    # The demonstrations' lane path in the vehicle frame gives the same path for the same pose.
    vehicle = _vehicle_frame(road[4:24], origin + 1.5 * right, yaw + np.radians(10.0))
    np.testing.assert_allclose(vehicle_frame_path(vehicle)[:15], seen[:15], atol=0.1)


def test_the_aligned_path_does_not_follow_the_chain_back_through_a_fold():
    # A teach drive that went 10 m east, turned back on itself and went 10 m west 2 m further north.
    out = np.column_stack([np.arange(0.0, 11.0), np.zeros(11)])
    back = np.column_stack([np.arange(10.0, -31.0, -1.0), np.full(41, 2.0)])
    chain = np.vstack([out, [[10.5, 1.0]], back])
    vertex = 13  # on the way back, 9 m east (2.2 m of chain past the turn)
    # The vehicle stands on the way out, nearer the chain behind the vertex than the chain ahead of it.
    path = aligned_path(chain, vertex, np.array([7.5, 0.2]), np.pi)
    assert path[0, 1] < -1.0  # the way back, 2 m north: to the vehicle's right when it faces west


def test_vehicle_frame_noise_moves_the_path_as_the_pose_error_does():
    lane = np.column_stack([np.arange(1.0, 21.0), np.zeros(20)]).astype(np.float32)
    np.testing.assert_allclose(vehicle_frame_path(lane)[:, 1], 0.0, atol=1e-9)
    left = vehicle_frame_path(lane, 0.0, 0.4, 0.0)  # a pose estimate 0.4 m left: the lane seems 0.4 m right
    np.testing.assert_allclose(left[:, 1], -0.4, atol=1e-9)
    turned = vehicle_frame_path(lane, 0.0, 0.0, np.radians(5.0))  # turned left: the lane bends away to the right
    assert turned[10, 1] < -0.8
