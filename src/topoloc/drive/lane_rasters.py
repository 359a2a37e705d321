"""Rasters around a route (cells of :data:`CELL_M`): roads drawn as wide as their carriageways, and the lane points
that lie on another road's carriageway too (:func:`shared_samples`)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

CELL_M = 0.25
#: Margin (m) of the rasters around a route's centre line.
RASTER_MARGIN_M = 40.0
#: Lane points this close to a junction are not counted as shared with the crossing roads (:func:`shared_samples`).
JUNCTION_M = 15.0


def road_raster(lines: list[tuple[NDArray[np.float64], float]], origin: tuple[float, float], shape: tuple[int, int],
                margin_m: float) -> NDArray[np.uint8]:
    """A raster of ``shape`` (cells of :data:`CELL_M`, top-left corner at map position ``origin``): 1 on every
    polyline of ``lines`` (coordinates, carriageway width) drawn as wide as its carriageway plus ``margin_m`` each side."""
    out = np.zeros(shape, np.uint8)
    for coords, width in lines:
        px = np.round(np.column_stack([(coords[:, 0] - origin[0]) / CELL_M, (origin[1] - coords[:, 1]) / CELL_M]) * 4)
        thick = max(1, round((width + 2 * margin_m) / CELL_M))
        cv2.polylines(out, [px.astype(np.int32)], False, 1, thick, cv2.LINE_8, 2)
    return out


def shared_samples(xy: NDArray[np.float64], others: NDArray[np.uint8], origin: tuple[float, float],
                   junctions: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which lane points ``xy`` lie on the carriageway of a road not on the route (raster ``others``) more than
    :data:`JUNCTION_M` from every junction: where two roads are drawn over each other (a service road beside a street,
    the two ways of a dual carriageway drawn too wide), and the camera shows one surface with no sign of which is the
    route's. Near a junction the crossing roads' carriageways cover the lane as they should."""
    rows = ((origin[1] - xy[:, 1]) / CELL_M).astype(int)
    cols = ((xy[:, 0] - origin[0]) / CELL_M).astype(int)
    h, w = others.shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    on = np.zeros(len(xy), bool)
    on[inside] = others[rows[inside], cols[inside]] > 0
    if on.any() and len(junctions):
        dist, _ = cKDTree(junctions).query(xy[on])
        on[np.flatnonzero(on)[dist <= JUNCTION_M]] = False
    return on
