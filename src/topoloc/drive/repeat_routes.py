"""The evaluation routes of teach and repeat: stretches of the teach route, each with the map of its own stretch of
the teach drive and each map vertex's arc length along the lane (``drive.follow.routes``, ``drive.follow.length_m``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.drive_route import DriveRoute
from topoloc.errors import InputError
from topoloc.place.topometric_map import TopometricMap


def vertex_lane_s(route: DriveRoute, topo: TopometricMap) -> NDArray[np.float64]:
    """Arc length along the lane of every map vertex (ground-truth positions, projected in order).

    Vertices further along the map than the lane is long (a map of the whole teach route, a lane cut to its first
    metres) are at the lane's end: a route that later comes back past the cut part is not projected onto it.
    InputError when the map's vertices do not follow the route (a map of another route or region).
    """
    out, s, dist = np.full(len(topo), route.length_m), 0.0, []
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(topo.gt_xy, axis=0).T))])
    for k, xy in enumerate(topo.gt_xy):
        if along[k] > route.length_m + 10.0:
            break
        s, lateral, _ = route.project(xy, s, 5.0, 10.0)
        out[k] = s
        if s < route.length_m - 1.0:
            dist.append(abs(lateral))
    if not dist or float(np.median(dist)) > 2.5:
        raise InputError("map", "the topometric map's vertices do not follow the teach route of this config "
                         "(a map of another route or region)")
    return np.maximum.accumulate(out)


@dataclass
class RepeatRoute:
    """One evaluation route: the lane from ``start_m`` of the teach route, the map of its own stretch of the teach
    drive (its first vertex at the start) and each vertex's arc length along the lane."""

    start_m: float
    route: DriveRoute
    topo: TopometricMap
    lane_s: NDArray[np.float64]


def route_starts(teach_m: float, length_m: float | None, routes: int) -> list[float]:
    """Where ``routes`` evaluation routes of ``length_m`` (None: the whole teach route) start on a teach route of
    ``teach_m``: evenly from its start to ``length_m`` before its end. InputError naming ``drive.follow.routes`` when
    several routes would all be the same."""
    if routes < 1:
        raise InputError("drive.follow.routes", f"must be at least 1, got {routes}")
    room = teach_m - (teach_m if length_m is None else min(float(length_m), teach_m))
    if routes > 1 and room < 1.0:
        raise InputError("drive.follow.routes", f"{routes} routes need drive.follow.length_m shorter than the "
                         f"{teach_m:.0f} m teach route (it is {length_m})")
    return [float(v) for v in np.linspace(0.0, room, routes)]


def repeat_routes(teach: DriveRoute, topo: TopometricMap, length_m: float | None, routes: int) -> list[RepeatRoute]:
    """The evaluation routes of ``drive.follow`` (:func:`route_starts`) on the teach route ``teach`` and its map."""
    lane_s = vertex_lane_s(teach, topo)
    out = []
    for start in route_starts(teach.length_m, length_m, routes):
        route = teach.part(start, teach.length_m - start if length_m is None else float(length_m))
        start = float(teach.s[np.searchsorted(teach.s, start, side="left")])  # the part's first lane sample
        lo = int(np.searchsorted(lane_s, start, side="left"))
        hi = int(np.searchsorted(lane_s, start + route.length_m, side="right"))
        if hi - lo < 2:
            raise InputError("map", f"the topometric map has no vertices on the teach route from {start:.0f} m "
                             f"to {start + route.length_m:.0f} m")
        out.append(RepeatRoute(start, route, topo.part(lo, hi), lane_s[lo:hi] - start))
    return out


def intersections(command: np.ndarray) -> int:
    """Intersections on a stretch of map vertices: the runs of a command other than ``follow`` (index 0)."""
    command = np.asarray(command)
    return int(np.sum((command[1:] != 0) & (command[1:] != command[:-1])) + (len(command) > 0 and command[0] != 0))
