"""Drivable routes on the road graph: the lane to follow, the carriageways, the command ahead.

A :class:`DriveRoute` is a chain of road edges, each entered from a node, checked against one-way
restrictions. Its **lane** is the road's centre line shifted to the right (right-hand traffic) by a
quarter of the carriageway (the middle of the right half) where the images show a dashed centre line to keep
right of (two-way roads at least 6 m wide, :func:`topoloc.render.textures.has_centre_line`), and not at all on
other roads (one-way, or narrower and unmarked: a driver takes the middle, and a camera could not tell a lane
there from the middle), then smoothed with a Gaussian of ``smoothing_m`` (corners become curves), sampled every
:data:`DENSE_M`; bends still tighter than ``min_radius_m`` (the lane offset on the inside of a junction corner
can leave a radius of 1 m, which no car can follow) are widened by smoothing them further, locally
(:func:`topoloc.drive.lane_geometry.widen_bends`), so the vehicle can follow every lane it is given. The carriageway width is the
renderer's (:func:`topoloc.render.textures.carriageway_width`: what the images show): the road's OSM ``width`` tag,
else its ``lanes`` tag times a lane width, else a per-class default. Each lane sample carries its road edge and the **navigation command** of Cai & Wan
(``follow``, or ``left`` / ``right`` / ``straight`` within ``command_m`` before an intersection: the drive's heading
change from there to ``lookahead_m`` past it), from
:func:`topoloc.place.topometric_map.route_intersections`, the rule that labels the topometric map's vertices.

Two rasters (0.25 m cells) judge where the vehicle is: the **drivable area** (every road of the graph near
the route, as wide as its carriageway plus ``margin_m``) and the **corridor** (the route's own roads only).
A point off the drivable area is *off road*; on it but off the corridor, on a *wrong road*. Lane points on another
road's carriageway too, away from junctions, are **shared** (:func:`topoloc.drive.lane_rasters.shared_samples`): there the images show one surface
and cannot tell the route's road from the other; training and check routes keep clear of them
(``drive.lane.max_shared_m``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.lane_geometry import DENSE_M, lane_polyline, widen_bends
from topoloc.drive.lane_rasters import CELL_M, RASTER_MARGIN_M, road_raster, shared_samples
from topoloc.drive.route_planning import check_route
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.route import sample_route
from topoloc.place.topometric_map import route_intersections, vertex_commands
from topoloc.render.textures import MARKED_WIDTH_M, edge_widths, has_centre_line


@dataclass
class DriveRoute:
    """The lane of a route (see the module docstring): samples ``xy``, heading ``yaw``, arc length ``s``, road
    ``edge``, carriageway ``width``, ``command`` (index into :data:`topoloc.place.topometric_map.COMMANDS`) and ``shared`` (on another road's
    carriageway too, :func:`~topoloc.drive.lane_rasters.shared_samples`) every :data:`DENSE_M`."""

    edges: list[int]
    froms: list[int]
    xy: NDArray[np.float64]
    yaw: NDArray[np.float64]
    s: NDArray[np.float64]
    edge: NDArray[np.int64]
    width: NDArray[np.float64]
    command: NDArray[np.int64]
    shared: NDArray[np.bool_] = field(repr=False)
    drivable: NDArray[np.uint8] = field(repr=False)
    corridor: NDArray[np.uint8] = field(repr=False)
    origin: tuple[float, float] = (0.0, 0.0)  #: map position of the rasters' top-left corner
    #: per sample: the carriageway has a centre line (the lane keeps right of it); None: unknown (every sample unmarked)
    marked: NDArray[np.bool_] | None = field(default=None, repr=False)

    @property
    def length_m(self) -> float:
        """Length of the lane in metres."""
        return float(self.s[-1])

    def index(self, s: float) -> int:
        """The lane sample at arc length ``s`` (clamped)."""
        return int(np.clip(np.searchsorted(self.s, s), 0, len(self.s) - 1))

    def command_at(self, s: float) -> int:
        """Command index at arc length ``s``."""
        return int(self.command[self.index(s)])

    def point(self, s: float) -> NDArray[np.float64]:
        """Lane position at arc length ``s`` (clamped to the ends)."""
        return np.array([np.interp(s, self.s, self.xy[:, 0]), np.interp(s, self.s, self.xy[:, 1])])

    def point_ahead(self, s: float) -> NDArray[np.float64]:
        """Lane position at arc length ``s``, the lane extended straight on beyond its end (what a driver aims at there)."""
        if s <= self.length_m:
            return self.point(s)
        return self.xy[-1] + (s - self.length_m) * np.array([np.cos(self.yaw[-1]), np.sin(self.yaw[-1])])

    def project(self, xy: NDArray[np.float64], near_s: float | None = None, back_m: float = 10.0,
                ahead_m: float = 30.0) -> tuple[float, float, float]:
        """Arc length, signed lateral offset (+ right of the lane) and lane heading of the point nearest to ``xy``,
        searched within ``[near_s - back_m, near_s + ahead_m]`` (everywhere when ``near_s`` is None)."""
        lo, hi = 0, len(self.s)
        if near_s is not None:
            lo = int(np.searchsorted(self.s, near_s - back_m))
            hi = max(lo + 1, int(np.searchsorted(self.s, near_s + ahead_m)))
        d = np.hypot(*(self.xy[lo:hi] - np.asarray(xy, float)).T)
        k = lo + int(np.argmin(d))
        yaw = float(self.yaw[k])
        dx, dy = np.asarray(xy, float) - self.xy[k]
        along = dx * np.cos(yaw) + dy * np.sin(yaw)
        lateral = dx * np.sin(yaw) - dy * np.cos(yaw)
        return float(np.clip(self.s[k] + along, 0.0, self.s[-1])), float(lateral), yaw

    def _cell(self, xy: NDArray[np.float64]) -> tuple[int, int]:
        return int((self.origin[1] - xy[1]) / CELL_M), int((xy[0] - self.origin[0]) / CELL_M)

    def off_corridor(self) -> NDArray[np.bool_]:
        """Which lane samples lie off the route's own roads (a lane smoothed or widened out of a narrow road)."""
        rows = ((self.origin[1] - self.xy[:, 1]) / CELL_M).astype(int)
        cols = ((self.xy[:, 0] - self.origin[0]) / CELL_M).astype(int)
        h, w = self.corridor.shape
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        off = ~inside
        off[inside] = self.corridor[rows[inside], cols[inside]] == 0
        return off

    def on_drivable(self, xy: NDArray[np.float64]) -> bool:
        """Whether ``xy`` is on a carriageway (with the margin)."""
        r, c = self._cell(xy)
        h, w = self.drivable.shape
        return bool(0 <= r < h and 0 <= c < w and self.drivable[r, c])

    def on_corridor(self, xy: NDArray[np.float64]) -> bool:
        """Whether ``xy`` is on one of the route's roads (with the margin)."""
        r, c = self._cell(xy)
        h, w = self.corridor.shape
        return bool(0 <= r < h and 0 <= c < w and self.corridor[r, c])

    def cut(self, length_m: float) -> DriveRoute:
        """The first ``length_m`` metres of the lane (:meth:`part`)."""
        return self.part(0.0, length_m)

    def part(self, start_m: float, length_m: float, where: str = "drive.follow.length_m") -> DriveRoute:
        """The lane from arc length ``start_m`` on for ``length_m`` metres, its arc length counted from there; InputError
        naming ``where`` when that leaves no lane to drive. The drivable area is kept; the corridor keeps the cells of
        the route's roads near the part's lane only (within three quarters of the widest carriageway and 2 m: the lane
        keeps at most a quarter right of the centre line), so a car that leaves the part for a road the route takes
        before or after it is on a wrong road."""
        lo = int(np.searchsorted(self.s, start_m, side="left"))
        hi = int(np.searchsorted(self.s, start_m + length_m, side="right"))
        if hi - lo < 2:
            raise InputError(where, f"{length_m} m from {start_m:.0f} m leaves no lane to drive (the lane is "
                             f"{self.length_m:.0f} m long)")
        used = set(self.edge[lo:hi].tolist())
        keep = [i for i, e in enumerate(self.edges) if e in used]
        corridor = self.corridor
        if lo > 0 or hi < len(self.s):
            band = road_raster([(self.xy[lo:hi], 1.5 * float(self.width[lo:hi].max()))], self.origin, self.corridor.shape, 2.0)
            corridor = self.corridor & band
        return DriveRoute([self.edges[i] for i in keep], [self.froms[i] for i in keep], self.xy[lo:hi], self.yaw[lo:hi],
                          self.s[lo:hi] - self.s[lo], self.edge[lo:hi], self.width[lo:hi], self.command[lo:hi],
                          self.shared[lo:hi], self.drivable, corridor, self.origin,
                          None if self.marked is None else self.marked[lo:hi])

    @property
    def shared_m(self) -> float:
        """Metres of the lane on another road's carriageway too (:func:`~topoloc.drive.lane_rasters.shared_samples`)."""
        return float(self.shared.sum()) * DENSE_M

    @property
    def wide_middle_share(self) -> float:
        """Share of the lane in the middle of a carriageway at least :data:`~topoloc.render.textures.MARKED_WIDTH_M`
        wide (no centre line: a wide one-way road), where a lane kept right would be a quarter of the road off."""
        marked = np.zeros(len(self.s), bool) if self.marked is None else self.marked
        return float(np.mean(~marked & (self.width >= MARKED_WIDTH_M)))



def build_route(graph: RoadGraph, edges: list[int], froms: list[int], smoothing_m: float = 4.0,
                margin_m: float = 0.5, command_m: float = 20.0, lookahead_m: float = 10.0, straight_deg: float = 45.0,
                where: str = "route", min_radius_m: float = 5.0) -> DriveRoute:
    """The :class:`DriveRoute` of a chain of edges (checked with :func:`~topoloc.drive.route_planning.check_route`; bends
    widened to ``min_radius_m`` by :func:`~topoloc.drive.lane_geometry.widen_bends`).

    InputError naming ``where`` when the lane leaves the route's own roads (no vehicle could follow it and stay on them).
    """
    check_route(graph, edges, froms, where)
    centre, label = sample_route(graph, list(edges), list(froms), DENSE_M)
    if len(centre) < 8:
        raise InputError(where, "the route is shorter than 2 m")
    widths = edge_widths(graph.edges)
    width = widths[np.asarray(label, int)]
    marked = np.array([has_centre_line(w, int(graph.edges.oneway.iat[e]) == 0) for e, w in zip(label, width)])
    xy = widen_bends(lane_polyline(centre, np.where(marked, width / 4.0, 0.0), smoothing_m), min_radius_m, where)
    step = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(step)])
    d = np.gradient(xy, axis=0)
    yaw = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    crossings = route_intersections(graph, label, xy, lookahead_m, straight_deg, command_m)
    command = vertex_commands(xy, crossings, command_m)
    # Rasters around the route: every road nearby (drivable area) and the route's own roads (corridor).
    lo, hi = centre.min(axis=0) - RASTER_MARGIN_M, centre.max(axis=0) + RASTER_MARGIN_M
    origin = (float(lo[0]), float(hi[1]))
    shape = (int(np.ceil((hi[1] - lo[1]) / CELL_M)) + 1, int(np.ceil((hi[0] - lo[0]) / CELL_M)) + 1)
    near = [e for e in range(graph.num_edges) if np.any(np.all((graph.geometry[e] >= lo) & (graph.geometry[e] <= hi), axis=1))]
    drivable = road_raster([(graph.geometry[e], float(widths[e])) for e in near], origin, shape, margin_m)
    corridor = road_raster([(graph.geometry[e], float(widths[e])) for e in set(edges)],
                       origin, shape, margin_m)
    others = road_raster([(graph.geometry[e], float(widths[e])) for e in near if e not in set(edges)], origin, shape, 0.0)
    shared = shared_samples(xy, others, origin, graph.nodes.loc[graph.nodes.degree >= 3, ["x", "y"]].to_numpy(float))
    route = DriveRoute(list(edges), list(froms), xy, yaw, s, label, width, command, shared, drivable, corridor, origin, marked)
    off = route.off_corridor()
    if off.any():
        raise InputError(where, f"the lane leaves the route's roads at {s[int(np.argmax(off))]:.0f} m (a bend of a narrow "
                         f"road tighter than drive.lane.min_radius_m = {min_radius_m} m, or than the smoothing allows)")
    return route
