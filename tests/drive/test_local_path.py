"""Topo-LP's local path: the map's path and the demonstrations' lane path give the same image for the same road,
the vehicle's own offset is not in it, turns bend it the right way, and the training noise moves it. Topo-DLM's move:
one turn, where the path turns, by as much."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.drive.local_path import (
    PATH_PX,
    PLANE_POINTS,
    aligned_path,
    chain_frame,
    lane_frame_path,
    map_path,
    move_path,
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


def _turning(turns_deg: list[tuple[float, float, float]], start=(0.0, 0.0), heading_deg: float = 0.0) -> np.ndarray:
    """A path of 20 steps of 1 m from ``start`` that turns ``deg`` evenly from metre ``a`` to metre ``b`` for each
    ``(a, b, deg)`` of ``turns_deg``."""
    mid = np.arange(20) + 0.5
    heading = np.full(20, np.radians(heading_deg))
    for a, b, deg in turns_deg:
        heading += np.radians(deg) * np.clip((mid - a) / (b - a), 0.0, 1.0)
    steps = np.column_stack([np.cos(heading), np.sin(heading)])
    return np.vstack([start, np.asarray(start) + np.cumsum(steps, axis=0)])


def _turned(points: np.ndarray) -> float:
    d = np.diff(points, axis=0)
    return float(np.degrees(np.unwrap(np.arctan2(d[:, 1], d[:, 0])))[-1] - np.degrees(np.arctan2(d[0, 1], d[0, 0])))


def test_a_path_that_is_one_turn_is_its_own_move():
    for turn in ([(6.0, 14.0, -90.0)], [(3.0, 17.0, 135.0)], [(0.0, 20.0, 25.0)]):
        path = _turning(turn, start=(0.0, 0.6), heading_deg=4.0)  # the vehicle 0.6 m right of and 4 deg off the path
        move = move_path(path)
        assert np.abs(move - path).max() < 0.05, turn


def test_the_move_turns_where_and_as_much_as_the_path_and_keeps_its_start():
    # a sharp right turn made of two: 40 deg over 5-8 m, 95 deg over 9-13 m (135 deg in all, as the default run's)
    path = _turning([(5.0, 8.0, -40.0), (9.0, 13.0, -95.0)], start=(0.3, -0.8), heading_deg=-3.0)
    move = move_path(path)
    assert _turned(move) == pytest.approx(-135.0, abs=0.5)
    assert np.allclose(move[:5], path[:5])  # straight ahead up to the turn, from the path's point and heading
    assert np.hypot(*(move[-1] - path[-1])) < 1.5  # and it comes out where the path does, within a metre or so
    assert np.abs(move - path).max() > 0.2  # but it is one turn, not the path's two


@pytest.mark.parametrize("turns", [[(5.0, 9.0, -30.0), (11.0, 15.0, 30.0)], [(4.0, 12.0, 8.0)]])
def test_a_path_whose_turns_cancel_or_are_slight_is_a_straight_move(turns):
    path = _turning(turns, start=(0.0, 0.4), heading_deg=2.0)
    move = move_path(path)
    assert abs(_turned(move)) < 1e-9
    assert np.allclose(move[1] - move[0], path[1] - path[0])  # straight on along the path's first heading


def test_the_plane_of_a_move_is_the_plane_of_the_paths_move():
    path = _turning([(5.0, 8.0, -40.0), (9.0, 13.0, -95.0)])
    assert np.array_equal(path_plane(path, "move"), path_plane(move_path(path)))
    assert not np.array_equal(path_plane(path, "move"), path_plane(path))
    with pytest.raises(ValueError, match="path form"):
        path_plane(path, "turns")
