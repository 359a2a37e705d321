"""Column ray casting against vertical walls, vectorised over image columns and wall segments.

With planar motion and vertical walls, the scene seen through one image column is decided by one ray in
the ground plane: the nearest wall segment it crosses. In the camera frame (x right, z forward) the ray of
a column with slope ``k = (u - cx) / f`` is ``x = k z``; a segment ``P0 + s (P1 - P0)`` crosses it at

    s = (k z0 - x0) / ((x1 - x0) - k (z1 - z0)),   depth z = z0 + s (z1 - z0),

valid for ``0 <= s <= 1`` and ``z > near``. The depth along the optical axis is what a pinhole camera
needs directly (image rows scale with ``1 / z``). Segments are pre-split into short pieces and kept in a
k-d tree, so each frame only tests the pieces within the view distance, in front of the camera and facing
it (rings are oriented with the building on their left: a wall seen from inside is culled).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

MAX_PIECE_M = 8.0


@dataclass
class Walls:
    """Wall pieces: ends ``p0``, ``p1`` (n, 2) map metres, ``tile`` (facade texture), ``height`` metres,
    ``u0`` metres along the building outline at ``p0`` (texture coordinate), outward unit ``normal``."""

    p0: NDArray[np.float64]
    p1: NDArray[np.float64]
    tile: NDArray[np.int32]
    height: NDArray[np.float32]
    u0: NDArray[np.float64]
    normal: NDArray[np.float64] = field(init=False)
    length: NDArray[np.float64] = field(init=False)
    _tree: cKDTree | None = field(init=False, default=None, repr=False)

    def __post_init__(self) -> None:
        d = self.p1 - self.p0
        self.length = np.hypot(d[:, 0], d[:, 1])
        self.normal = np.column_stack([d[:, 1], -d[:, 0]]) / np.maximum(self.length, 1e-12)[:, None]
        if len(self.p0):
            self._tree = cKDTree((self.p0 + self.p1) / 2.0)

    def __len__(self) -> int:
        return len(self.p0)

    @classmethod
    def from_rings(cls, rings: list[tuple[NDArray[np.float64], int, float]]) -> Walls:
        """Walls of closed rings ``(coords (n, 2) with the building on the left, tile, height)``."""
        p0, p1, tile, height, u0 = [], [], [], [], []
        for coords, tile_id, h in rings:
            coords = np.asarray(coords, float)
            if len(coords) < 2:
                continue
            if np.allclose(coords[0], coords[-1]):
                coords = coords[:-1]
            a, b = coords, np.roll(coords, -1, axis=0)
            seg = np.hypot(*(b - a).T)
            start = np.concatenate([[0.0], np.cumsum(seg)[:-1]])
            for pa, pb, length, s0 in zip(a, b, seg, start):
                if length < 1e-6:
                    continue
                pieces = int(np.ceil(length / MAX_PIECE_M))
                t = np.linspace(0.0, 1.0, pieces + 1)
                pts = pa + t[:, None] * (pb - pa)
                p0.append(pts[:-1])
                p1.append(pts[1:])
                u0.append(s0 + t[:-1] * length)
                tile.append(np.full(pieces, tile_id))
                height.append(np.full(pieces, h))
        if not p0:
            empty = np.empty((0, 2))
            return cls(empty, empty.copy(), np.empty(0, np.int32), np.empty(0, np.float32), np.empty(0))
        return cls(np.concatenate(p0), np.concatenate(p1), np.concatenate(tile).astype(np.int32),
                   np.concatenate(height).astype(np.float32), np.concatenate(u0))

    def near(self, xy: NDArray[np.float64], radius: float) -> NDArray[np.int64]:
        """Indices of the pieces whose midpoint lies within ``radius`` (+ half a piece) of ``xy``."""
        if self._tree is None:
            return np.empty(0, np.int64)
        return np.asarray(self._tree.query_ball_point(xy, radius + MAX_PIECE_M / 2.0), dtype=np.int64)


@dataclass(frozen=True)
class Hits:
    """Per image column: ``depth`` (inf where no wall), wall piece index ``piece`` (-1 none), ``along`` metres from its p0."""

    depth: NDArray[np.float32]
    piece: NDArray[np.int64]
    along: NDArray[np.float32]


def cast(walls: Walls, candidates: NDArray[np.int64], cam: NDArray[np.float64], yaw: float,
         slopes: NDArray[np.float32], near: float = 0.3) -> Hits:
    """Nearest wall of every column of a camera at map ``cam`` looking along ``yaw`` (radians from east)."""
    n_cols = len(slopes)
    miss = Hits(np.full(n_cols, np.inf, np.float32), np.full(n_cols, -1, np.int64), np.zeros(n_cols, np.float32))
    if len(candidates) == 0:
        return miss
    fwd = np.array([np.cos(yaw), np.sin(yaw)])
    right = np.array([fwd[1], -fwd[0]])
    a, b = walls.p0[candidates] - cam, walls.p1[candidates] - cam
    x0, z0, x1, z1 = a @ right, a @ fwd, b @ right, b @ fwd
    # Facing the camera (camera on the outer side of the wall), not entirely behind it or outside the view.
    k_lo, k_hi = float(slopes[0]), float(slopes[-1])
    ahead = (z0 > 0) & (z1 > 0)
    d = b - a
    keep = (a[:, 1] * d[:, 0] - a[:, 0] * d[:, 1] > 0) & ((z0 > near) | (z1 > near)) \
        & ~(ahead & (x0 > k_hi * z0) & (x1 > k_hi * z1)) & ~(ahead & (x0 < k_lo * z0) & (x1 < k_lo * z1))
    if not keep.any():
        return miss
    idx = candidates[keep]
    x0, z0 = x0[keep].astype(np.float32), z0[keep].astype(np.float32)
    dx, dz = x1[keep].astype(np.float32) - x0, z1[keep].astype(np.float32) - z0
    k = slopes[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (k * z0 - x0) / (dx - k * dz)
    depth = z0 + s * dz
    valid = (s >= -1e-5) & (s <= 1.0 + 1e-5) & (depth > near)
    depth = np.where(valid, depth, np.float32(np.inf))
    j = np.argmin(depth, axis=1)
    cols = np.arange(n_cols)
    best = depth[cols, j]
    hit = np.isfinite(best)
    piece = np.where(hit, idx[j], -1)
    along = np.where(hit, np.clip(s[cols, j], 0.0, 1.0) * walls.length[idx[j]].astype(np.float32), 0.0)
    return Hits(best.astype(np.float32), piece, along.astype(np.float32))
