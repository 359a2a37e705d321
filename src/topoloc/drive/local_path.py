"""The local-path command of Topo-LP (Cai & Wan): a small top-down image of the path ahead from the topometric map.

* **In closed loop** (:func:`map_path`): the localized vertex's next ``PATH_AHEAD_M`` metres of the map's
  path-integrated chain (``TopometricMap.xy``, the teach drive's odometry), in the frame of that vertex (origin at
  the vertex, x along the chain's heading there, y to the left). The vehicle's own offset from the teach drive is
  not in it: the camera image has to tell that.
* **In training** (:func:`lane_frame_path`): the same from the demonstrations' lane path (recorded in the vehicle
  frame, :data:`topoloc.drive.demonstrations.LOCAL_PATH_M` metres every metre): re-expressed in the frame of the
  lane point at the vehicle's progress shifted by ``shift_m`` and turned by ``yaw_rad``, the localization error the
  paper adds to the path in training.
* **In the vehicle's frame** (``drive.network.path_frame: aligned``, a deviation from the paper): in closed loop
  (:func:`aligned_path`) the same chain from the point nearest the vehicle, in the vehicle's frame as
  :class:`topoloc.drive.ground_alignment.PoseTracker` estimates it; in training (:func:`vehicle_frame_path`) the
  lane path from the point nearest a frame moved from the vehicle's by the tracker's error.
* **Raster** (:func:`raster`): ``PATH_PX`` x ``PATH_PX`` pixels, ``PATH_AHEAD_M`` metres ahead (bottom row: the
  reference point) and half that to either side, the path drawn as a one-pixel anti-aliased line.
* **Plane** (:func:`path_plane`): what Topo-LP is told, ``PATH_PX + 1`` rows of ``PATH_PX``: the raster on top and,
  in the last row, the path's points 1, 2, ... ``PATH_PX // 2`` m ahead as numbers (x, y in metres, in turn), which a
  Topo-LP with ``path_prior`` reads as its lane points before the image's correction.
* **The move** (:func:`move_path`, the path form ``move``: what Topo-DLM is told with ``drive.network.dlm_command:
  move``): the path reduced to one turn, three numbers: where it begins, by how much it turns, over how many metres.
  Drawn again from the path's first point and heading, it is what the plane then shows.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

PATH_PX = 32
PATH_AHEAD_M = 20.0  # as far as the demonstrations record the lane (LOCAL_PATH_M)
PLANE_POINTS = PATH_PX // 2  # the points 1 .. 16 m ahead fill the plane's last row
_STEP_M = 1.0
#: What a controller told a path is told of it (``path_form``): the path itself, or its move (:func:`move_path`).
PATH_FORMS = ("path", "move")
#: A path that turns less than this in all (deg) is told as a straight move.
MOVE_MIN_TURN_DEG = 10.0


def _along(points: NDArray[np.float64], arc: NDArray[np.float64], query: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points of a polyline (with arc lengths ``arc``) at arc lengths ``query``, extended straight beyond both ends."""
    out = np.column_stack([np.interp(query, arc, points[:, 0]), np.interp(query, arc, points[:, 1])])
    for end, sel, a, b in ((0, query < arc[0], 0, 1), (-1, query > arc[-1], -2, -1)):
        if sel.any():
            d = points[b] - points[a]
            d = d / max(float(np.hypot(*d)), 1e-9)
            out[sel] = points[end] + (query[sel] - arc[end])[:, None] * d
    return out


def _in_frame(points: NDArray[np.float64], origin: NDArray[np.float64], yaw: float) -> NDArray[np.float64]:
    """Points in the frame at ``origin`` with heading ``yaw`` (x ahead, y left)."""
    d = points - origin
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c])


def _reframed(points: NDArray[np.float64], arc: NDArray[np.float64], start: float, yaw_rad: float) -> NDArray[np.float64]:
    """The polyline's next ``PATH_AHEAD_M`` metres from arc length ``start`` in the frame there (turned by ``yaw_rad``)."""
    ahead = _along(points, arc, start + np.arange(0.0, PATH_AHEAD_M + _STEP_M, _STEP_M))
    heading = ahead[2] - ahead[0]
    return _in_frame(ahead, ahead[0], float(np.arctan2(heading[1], heading[0])) + yaw_rad)


def lane_frame_path(path: NDArray[np.float32], shift_m: float = 0.0, yaw_rad: float = 0.0) -> NDArray[np.float64]:
    """A demonstration step's local path (vehicle frame, points 1, 2, ... m ahead on the lane) in the lane's frame
    ``shift_m`` along it (see the module docstring)."""
    pts = np.asarray(path, float)
    pts = np.vstack([2.0 * pts[0] - pts[1], pts])  # the lane point at the vehicle's progress
    return _reframed(pts, np.arange(len(pts), dtype=float), float(shift_m), float(yaw_rad))


def _chain(xy: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The chain's points without repeats (a stop has no heading) and their arc lengths."""
    xy = np.asarray(xy, float)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    keep = np.concatenate([[True], np.diff(arc) > 1e-6])
    return xy[keep], arc[keep]


def _vertex_arc(xy: NDArray[np.float64], vertex: int) -> float:
    """The arc length of vertex ``vertex`` along the chain."""
    steps = np.hypot(*np.diff(np.asarray(xy, float), axis=0).T)
    return float(steps[: int(vertex)].sum())


def chain_frame(xy: NDArray[np.float64], vertex: int) -> tuple[NDArray[np.float64], float]:
    """The frame :func:`map_path` expresses vertex ``vertex``'s path in: its point on the chain and the heading (rad)
    of the chord to the chain 2 m on."""
    points, arc = _chain(xy)
    ahead = _along(points, arc, _vertex_arc(xy, vertex) + np.array([0.0, 2.0 * _STEP_M]))
    return ahead[0], float(np.arctan2(*(ahead[1] - ahead[0])[::-1]))


def map_path(xy: NDArray[np.float64], vertex: int) -> NDArray[np.float64]:
    """The map chain's next metres from ``vertex`` in that vertex's frame (see the module docstring)."""
    origin, yaw = chain_frame(xy, vertex)
    points, arc = _chain(xy)
    start = _vertex_arc(xy, vertex)
    return _in_frame(_along(points, arc, start + np.arange(0.0, PATH_AHEAD_M + _STEP_M, _STEP_M)), origin, yaw)


def _nearest_arc(points: NDArray[np.float64], arc: NDArray[np.float64], at: NDArray[np.float64], lo: float,
                 hi: float) -> float:
    """The arc length of the polyline's point nearest ``at`` among its segments between arc lengths ``lo`` and ``hi``."""
    a, b = points[:-1], points[1:]
    d = b - a
    t = np.clip(((at - a) * d).sum(axis=1) / np.maximum((d * d).sum(axis=1), 1e-12), 0.0, 1.0)
    foot = a + t[:, None] * d
    s = arc[:-1] + t * (arc[1:] - arc[:-1])
    dist = np.where((s >= lo) & (s <= hi), np.hypot(*(foot - at).T), np.inf)
    return float(s[int(np.argmin(dist))]) if np.isfinite(dist).any() else float(np.clip(lo, arc[0], arc[-1]))


def _ahead_in_frame(points: NDArray[np.float64], arc: NDArray[np.float64], origin: NDArray[np.float64], yaw: float,
                    lo: float, hi: float) -> NDArray[np.float64]:
    """The polyline's next ``PATH_AHEAD_M`` metres, every metre, from its point nearest ``origin`` (between arc lengths
    ``lo`` and ``hi``), in the frame at ``origin`` with heading ``yaw``."""
    start = _nearest_arc(points, arc, np.asarray(origin, float), lo, hi)
    return _in_frame(_along(points, arc, start + np.arange(0.0, PATH_AHEAD_M + _STEP_M, _STEP_M)), origin, yaw)


def aligned_path(xy: NDArray[np.float64], vertex: int, centre: NDArray[np.float64], yaw: float,
                 behind_m: float = 3.0, ahead_m: float = 10.0) -> NDArray[np.float64]:
    """The map chain's next metres from its point nearest the vehicle (``centre``, ``yaw`` in the chain's
    coordinates), in the vehicle's frame. The point is sought from ``behind_m`` before vertex ``vertex`` to
    ``ahead_m`` after it: where the chain folds back on itself (the inside of a tight turn, offset from the road),
    the chain behind the vertex can pass nearer the vehicle than the chain it is to follow."""
    points, arc = _chain(xy)
    at = _vertex_arc(xy, vertex)
    return _ahead_in_frame(points, arc, centre, yaw, at - behind_m, at + ahead_m)


def vehicle_frame_path(path: NDArray[np.float32], forward_m: float = 0.0, left_m: float = 0.0,
                       yaw_rad: float = 0.0) -> NDArray[np.float64]:
    """A demonstration step's local path (vehicle frame, points 1, 2, ... m ahead on the lane) from its point nearest
    a frame ``forward_m`` ahead of and ``left_m`` left of the vehicle, turned by ``yaw_rad``, in that frame."""
    pts = np.asarray(path, float)
    pts = np.vstack([2.0 * pts[0] - pts[1], pts])  # the lane point at the vehicle's progress
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    return _ahead_in_frame(pts, arc, np.array([forward_m, left_m]), float(yaw_rad), -np.inf, np.inf)


def path_input(path: np.ndarray, frame: str, forward_m: float = 0.0, left_m: float = 0.0,
               yaw_rad: float = 0.0, form: str = "path") -> np.ndarray:
    """The local-path plane of a recorded lane path (vehicle frame) in ``frame`` (``drive.network.path_frame``):
    ``lane``, the lane's frame ``forward_m`` along it and turned by ``yaw_rad`` (``left_m`` unused); ``aligned``, the
    vehicle's frame moved by ``forward_m``, ``left_m`` and turned by ``yaw_rad``; told in ``form`` (:func:`path_plane`)."""
    if frame == "aligned":
        return path_plane(vehicle_frame_path(path, forward_m, left_m, yaw_rad), form)
    return path_plane(lane_frame_path(path, forward_m, yaw_rad), form)


def move_path(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """The move of a path (frame coordinates, metres, every metre from the reference point): the path's total turn
    ``theta`` drawn as one steady turn over the metres where the path does the middle 80 % of it, widened by an
    eighth of that span at each end, straight before and after, from the path's first point and first heading and
    with its step lengths. A path turning less than :data:`MOVE_MIN_TURN_DEG` in all is a straight move; an S-bend
    whose turns cancel is one too (a move is one turn)."""
    p = np.asarray(points, float)
    d = np.diff(p, axis=0)
    step = np.hypot(*d.T)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    turned = heading - heading[0]
    theta = float(turned[-1])
    if abs(theta) < np.radians(MOVE_MIN_TURN_DEG):
        move = np.full(len(step), heading[0])
    else:
        mid = np.concatenate([[0.0], np.cumsum(step)])[:-1] + 0.5 * step
        done = np.maximum.accumulate(turned / theta)
        begin, end = (float(np.interp(q, done, mid)) for q in (0.1, 0.9))
        widen = max(end - begin, 1e-3) / 8.0
        move = heading[0] + theta * np.clip((mid - begin + widen) / (end - begin + 2.0 * widen), 0.0, 1.0)
    out = np.empty_like(p)
    out[0] = p[0]
    out[1:] = p[0] + np.cumsum(step[:, None] * np.column_stack([np.cos(move), np.sin(move)]), axis=0)
    return out


def raster(points: NDArray[np.float64]) -> NDArray[np.uint8]:
    """The path (frame coordinates, metres) drawn top-down as a ``PATH_PX`` x ``PATH_PX`` image (see the module docstring)."""
    scale = (PATH_PX - 1) / PATH_AHEAD_M
    cols = (PATH_PX - 1) / 2.0 - points[:, 1] * scale
    rows = (PATH_PX - 1) - points[:, 0] * scale
    image = np.zeros((PATH_PX, PATH_PX), np.uint8)
    pixels = np.round(np.column_stack([cols, rows]) * 16).astype(np.int32)  # 4 fractional bits
    cv2.polylines(image, [pixels], False, 255, 1, cv2.LINE_AA, shift=4)
    return image


def path_plane(points: NDArray[np.float64], form: str = "path") -> NDArray[np.float32]:
    """The input of a controller told a path (frame coordinates, metres, every metre from the reference point), in
    ``form`` (:data:`PATH_FORMS`: the path, or its :func:`move_path`): its raster in the top ``PATH_PX`` rows, its
    points 1 .. :data:`PLANE_POINTS` m ahead in the last row (see the module docstring)."""
    if form not in PATH_FORMS:
        raise ValueError(f"path form {form!r} is not one of {', '.join(PATH_FORMS)}")
    if form == "move":
        points = move_path(points)
    plane = np.zeros((PATH_PX + 1, PATH_PX), np.float32)
    plane[:PATH_PX] = raster(points)
    plane[PATH_PX] = np.asarray(points, np.float32)[1:PLANE_POINTS + 1].reshape(-1)
    return plane
