"""Drivable routes on the road graph: the lane to follow, the carriageways, the command ahead.

A :class:`DriveRoute` is a chain of road edges, each entered from a node, checked against one-way
restrictions. Its **lane** is the road's centre line shifted to the right (right-hand traffic) by a
quarter of the carriageway (the middle of the right half) where the images show a dashed centre line to keep
right of (two-way roads at least 6 m wide, :func:`topoloc.render.textures.has_centre_line`), and not at all on
other roads (one-way, or narrower and unmarked: a driver takes the middle, and a camera could not tell a lane
there from the middle), then smoothed with a Gaussian of ``smoothing_m`` (corners become curves), sampled every
:data:`DENSE_M`; bends still tighter than ``min_radius_m`` (the lane offset on the inside of a junction corner
can leave a radius of 1 m, which no car can follow) are widened by smoothing them further, locally
(:func:`widen_bends`), so the vehicle can follow every lane it is given. The carriageway width is the
renderer's (:func:`topoloc.render.textures.carriageway_width`: what the images show): the road's OSM ``width`` tag,
else its ``lanes`` tag times a lane width, else a per-class default. Each lane sample carries its road edge and the **navigation command** of Cai & Wan
(``follow``, or ``left`` / ``right`` / ``straight`` within ``command_m`` before an intersection: the drive's heading
change from there to ``lookahead_m`` past it), from
:func:`topoloc.place.topometric_map.route_intersections`, the rule that labels the topometric map's vertices.

Two rasters (0.25 m cells) judge where the vehicle is: the **drivable area** (every road of the graph near
the route, as wide as its carriageway plus ``margin_m``) and the **corridor** (the route's own roads only).
A point off the drivable area is *off road*; on it but off the corridor, on a *wrong road*. Lane points on another
road's carriageway too, away from junctions, are **shared** (:func:`shared_samples`): there the images show one surface
and cannot tell the route's road from the other; training and check routes keep clear of them
(``drive.lane.max_shared_m``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import cv2
import networkx as nx
import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.route import sample_route
from topoloc.place.topometric_map import COMMANDS, route_intersections, vertex_commands
from topoloc.render.textures import edge_widths, has_centre_line

DENSE_M = 0.25
CELL_M = 0.25
RASTER_MARGIN_M = 40.0
#: Lane points this close to a junction are not counted as shared with the crossing roads (:func:`shared_samples`).
JUNCTION_M = 15.0


def check_route(graph: RoadGraph, edges: list[int], froms: list[int], where: str = "route") -> None:
    """InputError naming ``where`` unless the edges chain up end to end and none is driven against its one-way."""
    if not edges or len(edges) != len(froms):
        raise InputError(where, "a route needs at least one edge and one entry node per edge")
    for i, (e, f) in enumerate(zip(edges, froms)):
        if not 0 <= int(e) < graph.num_edges:
            raise InputError(where, f"edge {e} is not in the road graph ({graph.num_edges} edges)")
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        if f not in (u, v):
            raise InputError(where, f"edge {e} does not start at node {f}")
        ow = int(graph.edges.oneway.iat[e])
        if ow == 1 and f != u or ow == -1 and f != v:
            raise InputError(where, f"edge {e} ({graph.edges['name'].iat[e] or graph.edges.highway.iat[e]}) is one-way "
                             f"against the route: it cannot be driven from node {f}")
        if i and graph.other_end(edges[i - 1], froms[i - 1]) != f:
            raise InputError(where, f"edge {e} does not continue edge {edges[i - 1]}: the route is not connected")


def plan_route(graph: RoadGraph, start: int, goal: int) -> tuple[list[int], list[int]]:
    """The shortest drivable chain of edges from node ``start`` to node ``goal`` (one-way roads respected).

    InputError when either node is not in the graph or the goal cannot be reached (a disconnected goal, or
    one reachable only against one-way roads).
    """
    for name, node in (("start", start), ("goal", goal)):
        if node not in graph.nodes.index:
            raise InputError(f"route.{name}", f"node {node} is not in the road graph")
    directed = nx.DiGraph()
    for e in range(graph.num_edges):
        u, v, ow, length = (int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e]), int(graph.edges.oneway.iat[e]),
                            float(graph.edges.length_m.iat[e]))
        for a, b, ok in ((u, v, ow >= 0), (v, u, ow <= 0)):
            if ok and (not directed.has_edge(a, b) or directed[a][b]["length"] > length):
                directed.add_edge(a, b, length=length, edge=e)
    try:
        nodes = nx.shortest_path(directed, start, goal, weight="length")
    except (nx.NetworkXNoPath, nx.NodeNotFound) as err:
        raise InputError("route", f"no drivable route from node {start} to node {goal} (one-way roads or a "
                         "disconnected goal)") from err
    if len(nodes) < 2:
        raise InputError("route", "start and goal are the same node")
    return [int(directed[a][b]["edge"]) for a, b in itertools.pairwise(nodes)], [int(a) for a in nodes[:-1]]


def route_froms(graph: RoadGraph, edges: list[int], start_xy: NDArray[np.float64]) -> list[int]:
    """The entry node of each edge of a connected chain (the first: the end nearer to ``start_xy``)."""
    froms: list[int] = []
    for i, e in enumerate(edges):
        u, v = int(graph.edges.u.iat[e]), int(graph.edges.v.iat[e])
        if i == 0:
            nxt = {int(graph.edges.u.iat[edges[1]]), int(graph.edges.v.iat[edges[1]])} if len(edges) > 1 else set()
            shared = {u, v} & nxt
            froms.append(_nearer(graph, (u, v), start_xy) if len(shared) != 1 or u == v else (v if u in shared else u))
        else:
            froms.append(graph.other_end(edges[i - 1], froms[-1]))
    return froms


def _nearer(graph: RoadGraph, nodes: tuple[int, int], xy: NDArray[np.float64]) -> int:
    pos = graph.nodes.loc[list(nodes), ["x", "y"]].to_numpy(float)
    return int(nodes[int(np.argmin(np.hypot(*(pos - np.asarray(xy, float)).T)))])


@dataclass
class DriveRoute:
    """The lane of a route (see the module docstring): samples ``xy``, heading ``yaw``, arc length ``s``, road
    ``edge``, carriageway ``width``, ``command`` (index into :data:`COMMANDS`) and ``shared`` (on another road's
    carriageway too, :func:`shared_samples`) every :data:`DENSE_M`."""

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
            band = _raster([(self.xy[lo:hi], 1.5 * float(self.width[lo:hi].max()))], self.origin, self.corridor.shape, 2.0)
            corridor = self.corridor & band
        return DriveRoute([self.edges[i] for i in keep], [self.froms[i] for i in keep], self.xy[lo:hi], self.yaw[lo:hi],
                          self.s[lo:hi] - self.s[lo], self.edge[lo:hi], self.width[lo:hi], self.command[lo:hi],
                          self.shared[lo:hi], self.drivable, corridor, self.origin)

    @property
    def shared_m(self) -> float:
        """Metres of the lane on another road's carriageway too (:func:`shared_samples`)."""
        return float(self.shared.sum()) * DENSE_M


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


def _raster(lines: list[tuple[NDArray[np.float64], float]], origin: tuple[float, float], shape: tuple[int, int],
            margin_m: float) -> NDArray[np.uint8]:
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


def build_route(graph: RoadGraph, edges: list[int], froms: list[int], smoothing_m: float = 4.0,
                margin_m: float = 0.5, command_m: float = 20.0, lookahead_m: float = 10.0, straight_deg: float = 45.0,
                where: str = "route", min_radius_m: float = 5.0) -> DriveRoute:
    """The :class:`DriveRoute` of a chain of edges (checked with :func:`check_route`; bends widened to
    ``min_radius_m`` by :func:`widen_bends`).

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
    drivable = _raster([(graph.geometry[e], float(widths[e])) for e in near], origin, shape, margin_m)
    corridor = _raster([(graph.geometry[e], float(widths[e])) for e in set(edges)],
                       origin, shape, margin_m)
    others = _raster([(graph.geometry[e], float(widths[e])) for e in near if e not in set(edges)], origin, shape, 0.0)
    shared = shared_samples(xy, others, origin, graph.nodes.loc[graph.nodes.degree >= 3, ["x", "y"]].to_numpy(float))
    route = DriveRoute(list(edges), list(froms), xy, yaw, s, label, width, command, shared, drivable, corridor, origin)
    off = route.off_corridor()
    if off.any():
        raise InputError(where, f"the lane leaves the route's roads at {s[int(np.argmax(off))]:.0f} m (a bend of a narrow "
                         f"road tighter than drive.lane.min_radius_m = {min_radius_m} m, or than the smoothing allows)")
    return route


def command_name(index: int) -> str:
    """The name of a command index."""
    return COMMANDS[int(index)]
