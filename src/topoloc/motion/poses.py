"""KITTI-format files: poses, timestamps, calibration, per-frame GPS; planar views of poses; :class:`Odometry`.

KITTI poses are one 3x4 matrix ``[R | t]`` per line (12 numbers, row-major),
camera-to-world of camera 0: x right, y down, z forward. Seen from above, the
ground-plane track is ``(x, z)``; ``(x, z)`` is a counter-clockwise frame like
(east, north), so a rotation without reflection maps it onto the map.
Every reader raises :class:`~topoloc.errors.InputError` naming file and line.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.io import atomic_path


def read_poses(path: str | Path) -> NDArray[np.float64]:
    """Poses of a KITTI poses file as an ``(n, 4, 4)`` array."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "poses file not found")
    rows = []
    with path.open() as handle:
        for number, line in enumerate(handle, start=1):
            if not line.strip():
                continue
            parts = line.split()
            try:
                values = [float(p) for p in parts]
            except ValueError:
                raise InputError(f"{path}:{number}", f"not a number in a poses line: {line.strip()[:60]!r}") from None
            if len(values) != 12:
                raise InputError(f"{path}:{number}", f"a poses line needs 12 numbers (3x4 matrix), got {len(values)}")
            if not np.all(np.isfinite(values)):
                bad = [parts[i] for i in np.flatnonzero(~np.isfinite(values))]
                raise InputError(f"{path}:{number}", f"a poses line needs finite numbers, got {', '.join(bad)} "
                                                     f"(value {int(np.flatnonzero(~np.isfinite(values))[0]) + 1} of 12)")
            rows.append(values)
    if not rows:
        raise InputError(path, "poses file is empty")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = np.asarray(rows).reshape(-1, 3, 4)
    return poses


def write_poses(path: str | Path, poses: NDArray[np.float64]) -> None:
    """Write ``(n, 4, 4)`` (or ``(n, 3, 4)``) poses in KITTI format, atomically."""
    flat = np.asarray(poses)[:, :3, :4].reshape(len(poses), 12)
    with atomic_path(path) as tmp:
        np.savetxt(tmp, flat, fmt="%.6e")


def read_times(path: str | Path, count: int) -> NDArray[np.float64]:
    """Timestamps in seconds, one a line; must have ``count`` lines (one per pose)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "timestamps file not found")
    values = []
    with path.open() as handle:
        for number, line in enumerate(handle, start=1):
            if not line.strip():
                continue
            try:
                values.append(float(line.split()[0]))
            except ValueError:
                raise InputError(f"{path}:{number}", f"not a timestamp: {line.strip()[:60]!r}") from None
            if not np.isfinite(values[-1]):
                raise InputError(f"{path}:{number}", f"a timestamp needs a finite number, got {line.split()[0]}")
    if len(values) != count:
        raise InputError(path, f"{len(values)} timestamps for {count} poses")
    return np.asarray(values)


def read_gps(path: str | Path, count: int) -> NDArray[np.float64]:
    """Per-frame GPS ``(count, 2)`` as (lat, lon) from a CSV ``frame,lat,lon[,alt]`` (``#`` comments, header)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "GPS file not found")
    latlon: dict[int, tuple[float, float]] = {}
    with path.open() as handle:
        for number, line in enumerate(handle, start=1):
            text = line.strip()
            if not text or text.startswith("#") or text.lower().startswith("frame"):
                continue
            parts = text.split(",")
            try:
                frame, lat, lon = int(parts[0]), float(parts[1]), float(parts[2])
            except (ValueError, IndexError):
                raise InputError(f"{path}:{number}", f"expected 'frame,lat,lon[,alt]', got {text[:60]!r}") from None
            if not (np.isfinite(lat) and np.isfinite(lon)):
                raise InputError(f"{path}:{number}", f"lat/lon need finite numbers, got {parts[1].strip()}, {parts[2].strip()}")
            if not (-90 <= lat <= 90 and -180 <= lon <= 180):
                raise InputError(f"{path}:{number}", f"lat/lon out of range: {lat}, {lon}")
            latlon[frame] = (lat, lon)
    missing = [f for f in range(count) if f not in latlon]
    if missing:
        raise InputError(path, f"GPS file covers {count - len(missing)} of the {count} pose frames (first missing frame {missing[0]})")
    return np.array([latlon[f] for f in range(count)])


def read_calib(path: str | Path) -> tuple[NDArray[np.float64], float]:
    """Left intrinsics ``K`` (3x3) and stereo baseline in metres from a KITTI ``calib.txt`` (P0, P1)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "calib.txt not found (a KITTI sequence needs image_0/, image_1/ and calib.txt)")
    mats = {}
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if ":" not in line:
            continue
        key, _, rest = line.partition(":")
        try:
            mats[key.strip()] = np.array([float(v) for v in rest.split()])
        except ValueError:
            raise InputError(f"{path}:{number}", f"not a number in calibration line {key.strip()}") from None
    for key in ("P0", "P1"):
        if key not in mats or mats[key].size != 12:
            raise InputError(path, f"needs a {key} line with 12 numbers")
    p0, p1 = mats["P0"].reshape(3, 4), mats["P1"].reshape(3, 4)
    baseline = -(p1[0, 3] - p0[0, 3]) / p1[0, 0]
    if baseline <= 0:
        raise InputError(path, f"stereo baseline from P0/P1 must be positive, got {baseline:.4f} m")
    return p0[:, :3].copy(), float(baseline)


def planar_track(poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """Ground-plane positions ``(n, 2)`` = (x, z) of camera poses."""
    return np.column_stack([poses[:, 0, 3], poses[:, 2, 3]])


def planar_yaw(poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """Direction of the optical axis in the (x, z) plane, radians counter-clockwise from +x."""
    forward = poses[:, :3, 2]
    return np.arctan2(forward[:, 2], forward[:, 0])


def poses_from_planar(track: NDArray[np.float64], yaw: NDArray[np.float64]) -> NDArray[np.float64]:
    """KITTI camera poses (rotation about the down axis) from an (x, z) track and optical-axis yaw.

    ``yaw`` is counter-clockwise from +x in the (x, z) plane, as :func:`planar_yaw` returns it.
    """
    # Rotation about camera y by a, whose z column is (sin a, 0, cos a): that column's (x, z) is (sin a, cos a),
    # so its angle from +x is 90 deg - a.
    a = np.pi / 2.0 - np.asarray(yaw, float)
    c, s = np.cos(a), np.sin(a)
    poses = np.tile(np.eye(4), (len(track), 1, 1))
    poses[:, 0, 0], poses[:, 0, 2], poses[:, 2, 0], poses[:, 2, 2] = c, s, -s, c
    poses[:, 0, 3], poses[:, 2, 3] = track[:, 0], track[:, 1]
    return poses


@dataclass(frozen=True)
class Odometry:
    """A drive's planar odometry: positions ``xy`` (n, 2) in metres and ``yaw`` (n,) in radians, any frame.

    ``ds`` (n,): the measured signed distance of each frame's step (``ds[0] = 0``) where the odometry was
    integrated from such steps (:func:`topoloc.motion.noise.integrate_odometry`), else None.
    """

    xy: NDArray[np.float64]
    yaw: NDArray[np.float64]
    ds: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        if len(self.xy) != len(self.yaw):
            raise ValueError(f"{len(self.xy)} positions for {len(self.yaw)} headings")

    def __len__(self) -> int:
        return len(self.xy)

    @classmethod
    def from_poses(cls, poses: NDArray[np.float64]) -> Odometry:
        """From KITTI camera poses ``(n, 4, 4)``: the ground-plane track and the optical axis' yaw."""
        return cls(planar_track(poses), planar_yaw(poses))

    @classmethod
    def from_track(cls, xy: NDArray[np.float64]) -> Odometry:
        """From positions alone: the yaw is the direction of motion (reversing cannot be told apart)."""
        xy = np.asarray(xy, float)
        step = np.diff(xy, axis=0, append=xy[-1:] + (xy[-1:] - xy[-2:-1] if len(xy) > 1 else 0.0))
        moving = np.hypot(*step.T) > 1e-9
        yaw = np.arctan2(step[:, 1], step[:, 0])
        if moving.any():  # standing frames keep the last direction of motion
            index = np.maximum.accumulate(np.where(moving, np.arange(len(xy)), -1))
            first = int(np.argmax(moving))
            yaw = yaw[np.where(index >= 0, index, first)]
        return cls(xy, yaw)

    def cut(self, start: int) -> Odometry:
        """The drive from frame ``start`` on (nothing before it is known)."""
        ds = None if self.ds is None else np.concatenate([[0.0], self.ds[start + 1:]])
        return Odometry(self.xy[start:], self.yaw[start:], ds)

    @cached_property
    def driven_m(self) -> NDArray[np.float64]:
        """Metres driven up to each frame (path length of the positions)."""
        return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.xy, axis=0).T))])
