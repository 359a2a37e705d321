"""Rendered stereo sequences with known motion: textured planes seen by a KITTI-like stereo rig.

The scene is a corridor: a ground plane at ``y = 1.65`` m (camera height of
KITTI) and walls at ``x = -7`` and ``x = +7`` m, each with its own blurred
random texture. The rig is the KITTI 00 one: 1241 x 376 px, ``f = 718.856``
px, baseline 0.537 m. Used by the stereo VO tests and the odometry benchmark.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from topoloc.motion.poses import poses_from_planar

__all__ = ["BASELINE", "CALIB", "CX", "CY", "F", "H", "K", "W", "known_path", "render", "stereo_pair", "texture",
           "write_sequence"]

# The KITTI 00 rig: 1241 x 376, f = 718.856 px, baseline 0.537 m.
W, H, F, CX, CY, BASELINE = 1241, 376, 718.856, 607.1928, 185.2157, 0.537
K: NDArray[np.float64] = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
CALIB = (f"P0: {F} 0 {CX} 0 0 {F} {CY} 0 0 0 1 0\n"
         f"P1: {F} 0 {CX} {-F * BASELINE} 0 {F} {CY} 0 0 0 1 0\n")
TEXEL_M = 0.03


def texture(seed: int, size: int = 1024) -> NDArray[np.float32]:
    """A ``size`` x ``size`` blurred random texture with values in 0..255 (float32), reproducible from ``seed``."""
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.random((size, size), dtype=np.float32), (0, 0), 2.0)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    return (tex * 255).astype(np.float32)


_TEXTURES = [texture(s) for s in range(3)]
_U, _V = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
_RAYS = np.stack([(_U - CX) / F, (_V - CY) / F, np.ones_like(_U)], axis=-1)


def render(pose: NDArray[np.float64]) -> NDArray[np.uint8]:
    """Grayscale image seen by a camera with camera-to-world ``pose`` in a corridor: ground y = 1.65, walls x = +-7."""
    d = _RAYS @ pose[:3, :3].T
    c = pose[:3, 3]
    best = np.full((H, W), np.inf)
    out = np.full((H, W), 128.0, np.float32)
    planes = [(1, 1.65, (0, 2), 0), (0, -7.0, (2, 1), 1), (0, 7.0, (2, 1), 2)]
    for axis, value, (a, b), tex in planes:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (value - c[axis]) / d[..., axis]
        hit = (t > 0.1) & (t < best) & (t < 150)
        p = c + t[..., None] * d
        mx = (p[..., a] / TEXEL_M).astype(np.float32)
        my = (p[..., b] / TEXEL_M).astype(np.float32)
        sample = cv2.remap(_TEXTURES[tex], mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        out = np.where(hit, sample, out)
        best = np.where(hit, t, best)
    return np.clip(out, 0, 255).astype(np.uint8)


def stereo_pair(pose: NDArray[np.float64]) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Left and right images of the rig whose left camera has camera-to-world ``pose``."""
    right = pose.copy()
    right[:3, 3] = pose[:3, 3] + pose[:3, :3] @ np.array([BASELINE, 0, 0])
    return render(pose), render(right)


def known_path(n: int = 30, step: float = 1.0, turn_back_at: int | None = None) -> NDArray[np.float64]:
    """``n`` KITTI poses (n, 4, 4): forward at ``step`` m per frame, turning right 1.5 deg per frame in frames 10..19.

    The 15 deg heading carries the car sideways, into the right wall (x = 7) after about 40 m; for longer
    sequences, ``turn_back_at`` turns it back left by 15 deg in frames ``turn_back_at .. turn_back_at + 9``
    (30 keeps it about 5 m right of the centre line, 2 m from the wall).
    """
    frames = np.arange(n)
    yaw = np.pi / 2 - np.radians(1.5) * np.clip(frames - 10, 0, 10)
    if turn_back_at is not None:
        yaw += np.radians(1.5) * np.clip(frames - turn_back_at, 0, 10)
    xz = np.vstack([[0, 0], np.cumsum(step * np.column_stack([np.cos(yaw[1:]), np.sin(yaw[1:])]), axis=0)])
    return poses_from_planar(xz, yaw)


def write_sequence(root: Path, poses: NDArray[np.float64]) -> Path:
    """Write a KITTI sequence folder (``image_0/``, ``image_1/``, ``calib.txt``) rendered along ``poses``; returns ``root``."""
    root = Path(root)
    (root / "image_0").mkdir(parents=True)
    (root / "image_1").mkdir()
    (root / "calib.txt").write_text(CALIB)
    for k, pose in enumerate(poses):
        left, right = stereo_pair(pose)
        cv2.imwrite(str(root / "image_0" / f"{k:06d}.png"), left)
        cv2.imwrite(str(root / "image_1" / f"{k:06d}.png"), right)
    return root
