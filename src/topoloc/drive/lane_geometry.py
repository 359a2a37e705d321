"""The lane's polyline: the centre line shifted right and smoothed, its curvature, and bends widened to a radius a car
can follow (:mod:`topoloc.drive.drive_route` builds a route's lane with these)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from topoloc.errors import InputError

#: Spacing (m) of the dense lane samples.
DENSE_M = 0.25


def lane_polyline(centre: NDArray[np.float64], offset: NDArray[np.float64], smoothing_m: float) -> NDArray[np.float64]:
    """The dense centre line ``centre`` shifted ``offset`` metres to its right and smoothed over ``smoothing_m``."""
    sigma = max(smoothing_m / DENSE_M, 1.0)
    guide = gaussian_filter1d(centre, max(sigma, 3.0 * float(np.max(offset, initial=0.0)) / DENSE_M, 1.0), axis=0,
                              mode="nearest")
    tangent = np.gradient(guide, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    offset = gaussian_filter1d(offset, sigma, mode="nearest")
    xy = centre + offset[:, None] * np.column_stack([tangent[:, 1], -tangent[:, 0]])
    return gaussian_filter1d(xy, sigma, axis=0, mode="nearest")


def lane_curvature(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """|curvature| (1/m) of a dense polyline, averaged over about a metre (what a vehicle has to follow)."""
    d = np.gradient(xy, axis=0)
    yaw = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    step = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    return gaussian_filter1d(np.abs(np.gradient(yaw)) / step, 0.5 / DENSE_M, mode="nearest")


def widen_bends(xy: NDArray[np.float64], min_radius_m: float, where: str = "route",
                iterations: int = 400) -> NDArray[np.float64]:
    """The dense lane ``xy`` with every bend tighter than ``min_radius_m`` widened: the samples in and around such a
    bend are pulled towards a smoothed copy, repeatedly, until none is left (the rest of the lane is unchanged).

    InputError naming ``where`` when a bend cannot be widened enough (a turn back on the spot).
    """
    if min_radius_m <= 0:
        return xy
    limit, xy = 1.0 / min_radius_m, np.array(xy, float)
    for _ in range(iterations):
        tight = lane_curvature(xy) > limit
        if not tight.any():
            return xy
        weight = np.clip(4.0 * gaussian_filter1d(tight.astype(float), 2.0 / DENSE_M, mode="constant"), 0.0, 1.0)
        weight[[0, -1]] = 0.0  # the ends stay where they are
        xy += weight[:, None] * (gaussian_filter1d(xy, 1.0 / DENSE_M, axis=0, mode="nearest") - xy)
    worst = int(np.argmax(lane_curvature(xy)))
    s = float(np.hypot(*np.diff(xy[: worst + 1], axis=0).T).sum())
    raise InputError(where, f"the lane turns on a radius of {1.0 / lane_curvature(xy)[worst]:.1f} m at {s:.0f} m "
                     f"along it, tighter than drive.lane.min_radius_m = {min_radius_m} even after widening")
