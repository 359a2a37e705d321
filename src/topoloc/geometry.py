"""Planar geometry of motion on a road graph: turning angles, angle tokens, virtual nodes.

Conventions (metric, planar coordinates: x east, y north):

* The *heading change* ``delta`` at a node is the counter-clockwise angle from
  the entry direction (previous point -> node) to the exit direction (node ->
  next point), in (-180, 180].
* The *turning angle* ``phi`` (the paper's local angle) is measured in a frame
  at the node aligned with the entry direction: the angle swept clockwise from
  the ray back along the entry road to the ray along the exit road, in
  [0, 360). Hence ``phi = (180 - delta) mod 360``: straight on is 180, a left
  turn 90, a right turn 270, a U-turn 0.
* Angles are quantized into ``bins`` equal sectors whose centres are
  ``180 + (b - bins // 2) * 360 / bins``, so that straight on is the centre of
  bin ``bins // 2`` (the *straight token*): small heading noise on a straight
  road never flips the token. Each bin covers ``[centre - w/2, centre + w/2)``.
* Virtual nodes split a road every ``spacing`` metres from its start; each
  yields the straight token, which is how distance enters the token sequence.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

_LENGTH_EPS_M = 1e-6


def heading_change(prev: ArrayLike, cur: ArrayLike, nxt: ArrayLike) -> NDArray[np.float64] | float:
    """Counter-clockwise heading change in degrees, in (-180, 180], at ``cur``.

    Accepts single points (shape ``(2,)``) or stacks of points (shape ``(n, 2)``).
    """
    prev, cur, nxt = (np.asarray(p, dtype=float) for p in (prev, cur, nxt))
    entry = cur - prev
    exit_ = nxt - cur
    cross = entry[..., 0] * exit_[..., 1] - entry[..., 1] * exit_[..., 0]
    dot = entry[..., 0] * exit_[..., 0] + entry[..., 1] * exit_[..., 1]
    delta = np.degrees(np.arctan2(cross, dot))
    # arctan2 gives [-180, 180]; fold -180 onto 180 so a U-turn has one value.
    delta = np.where(delta <= -180.0, 180.0, delta)
    return float(delta) if np.ndim(delta) == 0 else delta


def turning_angle(prev: ArrayLike, cur: ArrayLike, nxt: ArrayLike) -> NDArray[np.float64] | float:
    """Local turning angle ``phi`` in degrees, in [0, 360): 180 straight, 90 left, 270 right, 0 U-turn."""
    phi = np.mod(180.0 - np.asarray(heading_change(prev, cur, nxt)), 360.0)
    return float(phi) if np.ndim(phi) == 0 else phi


def polyline_turning_angles(points: ArrayLike) -> NDArray[np.float64]:
    """Turning angles at the interior points of a polyline of shape ``(n, 2)``: ``n - 2`` values."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {pts.shape}")
    if len(pts) < 3:
        return np.empty(0)
    return np.atleast_1d(turning_angle(pts[:-2], pts[1:-1], pts[2:]))


def straight_token(bins: int) -> int:
    """The token of straight-on travel (and of every virtual node)."""
    _check_bins(bins)
    return bins // 2


def quantize_angle(phi: ArrayLike, bins: int) -> NDArray[np.int64] | int:
    """Token (bin index in ``[0, bins)``) of turning angle(s) ``phi`` in degrees."""
    _check_bins(bins)
    width = 360.0 / bins
    rel = np.mod(np.asarray(phi, dtype=float) - 180.0 + width / 2.0, 360.0)
    # Float rounding can put rel at exactly 360 after the mod: clip into the last sector.
    sector = np.minimum(np.floor(rel / width).astype(np.int64), bins - 1)
    token = np.mod(sector + bins // 2, bins)
    return int(token) if np.ndim(token) == 0 else token


def bin_centre(token: ArrayLike, bins: int) -> NDArray[np.float64] | float:
    """Centre angle in degrees of bin(s) ``token``: the inverse of :func:`quantize_angle`."""
    _check_bins(bins)
    centre = np.mod(180.0 + (np.asarray(token, dtype=float) - bins // 2) * 360.0 / bins, 360.0)
    return float(centre) if np.ndim(centre) == 0 else centre


def virtual_node_count(length_m: float, spacing_m: float) -> int:
    """Number of virtual nodes strictly inside a road of ``length_m``: one every ``spacing_m``."""
    if spacing_m <= 0:
        raise ValueError(f"spacing_m must be positive, got {spacing_m}")
    if length_m <= _LENGTH_EPS_M:
        return 0
    return max(0, math.ceil((length_m - _LENGTH_EPS_M) / spacing_m) - 1)


def virtual_node_offsets(length_m: float, spacing_m: float) -> NDArray[np.float64]:
    """Distances from the road's start of its virtual nodes: ``spacing, 2 * spacing, ... < length``."""
    count = virtual_node_count(length_m, spacing_m)
    return spacing_m * np.arange(1, count + 1, dtype=float)


def point_along(coords: ArrayLike, distance_m: float) -> NDArray[np.float64]:
    """The point ``distance_m`` along a polyline from its first point (clamped to its ends)."""
    pts = np.asarray(coords, dtype=float)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if distance_m <= 0 or cum[-1] == 0:
        return pts[0].copy()
    if distance_m >= cum[-1]:
        return pts[-1].copy()
    i = int(np.searchsorted(cum, distance_m, side="right")) - 1
    frac = (distance_m - cum[i]) / seg[i] if seg[i] > 0 else 0.0
    return pts[i] + frac * (pts[i + 1] - pts[i])


def _check_bins(bins: int) -> None:
    if int(bins) != bins or bins < 1:
        raise ValueError(f"bins must be a positive integer, got {bins}")
