"""The KITTI-like stereo rig: pinhole intrinsics scaled from KITTI 00, a horizontal baseline, a camera height.

KITTI 00's left grey camera (P0) has ``f = 718.856`` px and principal point ``(607.1928, 185.2157)`` at
1241 x 376 px. A rig of another size scales them with pixel centres at integer coordinates
(``u' = (u + 0.5) s - 0.5``), the focal length by the width's factor on both axes (square pixels), so a
rig of KITTI's aspect ratio has KITTI's field of view. The right camera sits ``baseline`` metres along the
left camera's x axis (to its right) with the same intrinsics: the pair is rectified by construction, and
a point at depth ``z`` has disparity ``f * baseline / z``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError

KITTI_SIZE = (1241, 376)
KITTI_BASELINE_M = 0.54
KITTI_F, KITTI_CX, KITTI_CY = 718.856, 607.1928, 185.2157
MIN_SIZE = (64, 48)


@dataclass(frozen=True)
class StereoRig:
    """Intrinsics (``f``, ``cx``, ``cy`` in px), image size, ``baseline`` and ``camera_height`` in metres."""

    width: int
    height: int
    f: float
    cx: float
    cy: float
    baseline: float
    camera_height: float

    @classmethod
    def kitti(cls, width: int, height: int, baseline: float, camera_height: float, where: str = "render") -> StereoRig:
        """The KITTI 00 intrinsics scaled to ``width`` x ``height``; InputError naming ``where.*`` on bad values."""
        if int(width) < MIN_SIZE[0] or int(height) < MIN_SIZE[1]:
            raise InputError(f"{where}.width" if int(width) < MIN_SIZE[0] else f"{where}.height",
                             f"image size {width}x{height} is too small; at least {MIN_SIZE[0]}x{MIN_SIZE[1]} px")
        if not baseline > 0:
            raise InputError(f"{where}.baseline_m", f"stereo baseline must be positive, got {baseline}")
        if not camera_height > 0:
            raise InputError(f"{where}.camera_height_m", f"camera height must be positive, got {camera_height}")
        sx, sy = width / KITTI_SIZE[0], height / KITTI_SIZE[1]
        return cls(int(width), int(height), KITTI_F * sx, (KITTI_CX + 0.5) * sx - 0.5, (KITTI_CY + 0.5) * sy - 0.5,
                   float(baseline), float(camera_height))

    @property
    def K(self) -> NDArray[np.float64]:  # noqa: N802 (the usual name of the intrinsic matrix)
        """3x3 intrinsic matrix of both cameras."""
        return np.array([[self.f, 0.0, self.cx], [0.0, self.f, self.cy], [0.0, 0.0, 1.0]])

    def column_slopes(self) -> NDArray[np.float64]:
        """``x / z`` of the ray through the centre of each image column (camera frame, x right)."""
        return (np.arange(self.width, dtype=np.float64) - self.cx) / self.f

    def row_slopes(self) -> NDArray[np.float64]:
        """``y / z`` of the ray through the centre of each image row (camera frame, y down)."""
        return (np.arange(self.height, dtype=np.float64) - self.cy) / self.f

    def disparity(self, depth_m: float | NDArray[np.float64]) -> float | NDArray[np.float64]:
        """Stereo disparity in pixels of a point at ``depth_m``."""
        return self.f * self.baseline / np.asarray(depth_m)

    def calib_text(self) -> str:
        """A KITTI ``calib.txt``: P0 / P2 left, P1 / P3 right (``-f * baseline`` in the fourth column), Tr identity."""
        def row(tx: float) -> str:
            values = [self.f, 0.0, self.cx, tx, 0.0, self.f, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
            return " ".join(f"{v:.12e}" for v in values)

        left, right = row(0.0), row(-self.f * self.baseline)
        identity = " ".join(f"{v:.12e}" for v in np.eye(3, 4).ravel())
        return f"P0: {left}\nP1: {right}\nP2: {left}\nP3: {right}\nTr: {identity}\n"
