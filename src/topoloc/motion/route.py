"""Routes on the road graph: random walks, sampled along the roads, smoothed into drivable camera paths.

The walk is :func:`random_route` (one-way roads respected, no U-turn except at dead ends), sampled with
:func:`sample_route` every 0.25 m. A walk that turns
back at a dead end is cut there (a camera cannot turn 180 degrees between two frames); of up to
``attempts`` walks the first at least ``length_m`` long is taken, else the longest. The polyline is then
shifted ``lane_offset_m`` to the right of the road centre line (right-hand traffic), smoothed with a
Gaussian of ``smoothing_m`` (corners become curves of a few metres radius) and resampled every
``spacing_m``, closer in curves: like a car that slows down to turn, the heading changes by at most
``max_turn_deg`` between frames (frames stay evenly spaced in time). The heading is the direction of
travel. Coordinates are in the graph's projected CRS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph

DENSE_M = 0.25


def random_route(graph: RoadGraph, length_m: float, rng: np.random.Generator, max_steps: int = 10000) -> tuple[list[int], list[int]]:
    """A random walk of edges (and the node each is entered from) of total length at least ``length_m``."""
    edges = graph.edges
    g = graph.graph
    nodes = [n for n in graph.nodes.index if graph.nodes.degree.at[n] >= 2] or list(graph.nodes.index)
    node = int(rng.choice(nodes))
    route: list[int] = []
    froms: list[int] = []
    total = 0.0
    for _ in range(max_steps):
        options = []
        for _, other, key in g.edges(node, keys=True):
            ow = edges.oneway.iat[key]
            if ow == 1 and edges.u.iat[key] != node or ow == -1 and edges.v.iat[key] != node:
                continue
            if route and key == route[-1] and g.degree(node) > 1:
                continue
            options.append(key)
        if not options:
            options = [route[-1]] if route else []
        if not options:
            break
        key = int(rng.choice(options))
        route.append(key)
        froms.append(node)
        total += float(edges.length_m.iat[key])
        node = graph.other_end(key, node)
        if total >= length_m:
            break
    return route, froms


def sample_route(graph: RoadGraph, route: list[int], froms: list[int], spacing_m: float) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Points every ``spacing_m`` along the route, and the edge of each."""
    pieces = [graph.edge_coords(e, f) for e, f in zip(route, froms)]
    coords = [pieces[0][:1]]
    labels = [np.array([route[0]])]
    for e, piece in zip(route, pieces):
        coords.append(piece[1:])
        labels.append(np.full(len(piece) - 1, e))
    pts = np.concatenate(coords)
    lab = np.concatenate(labels)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-6])
    pts, lab = pts[keep], lab[keep]
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    s = np.arange(0.0, cum[-1], spacing_m)
    x = np.interp(s, cum, pts[:, 0])
    y = np.interp(s, cum, pts[:, 1])
    idx = np.clip(np.searchsorted(cum, s, side="right"), 1, len(cum) - 1)
    return np.column_stack([x, y]), lab[idx].astype(np.int64)


@dataclass(frozen=True)
class CameraPath:
    """Map positions ``xy`` (n, 2) of the left camera, headings ``yaw`` (radians from east), edge per frame."""

    xy: NDArray[np.float64]
    yaw: NDArray[np.float64]
    edge_id: NDArray[np.int64]
    route: list[int]

    @property
    def length_m(self) -> float:
        """Driven length in metres."""
        return float(np.hypot(*np.diff(self.xy, axis=0).T).sum())


def smooth_path(dense: NDArray[np.float64], labels: NDArray[np.int64], spacing_m: float, smoothing_m: float,
                lane_offset_m: float, max_turn_deg: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Positions, headings and labels of frames along a smoothed, lane-offset copy of the polyline ``dense``.

    The lane offset is taken along the normals of a more strongly smoothed copy (so a sharp corner does not
    fold the offset line), then the offset line is smoothed with ``smoothing_m``. Frames are ``spacing_m``
    apart, closer in curves so that the heading turns by at most ``max_turn_deg`` between two frames.
    """
    sigma = smoothing_m / DENSE_M
    guide = gaussian_filter1d(dense, max(sigma, 3.0 * lane_offset_m / DENSE_M, 1.0), axis=0, mode="nearest")
    tangent = np.gradient(guide, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    xy = dense + lane_offset_m * np.column_stack([tangent[:, 1], -tangent[:, 0]])
    if sigma > 0:
        xy = gaussian_filter1d(xy, sigma, axis=0, mode="nearest")
    step = np.hypot(*np.diff(xy, axis=0).T)
    keep = np.concatenate([[True], step > 1e-6])
    xy, labels = xy[keep], labels[keep]
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    heading = np.gradient(xy, axis=0)
    angle = np.unwrap(np.arctan2(heading[:, 1], heading[:, 0]))
    # Frames per metre: 1 / spacing on straights, |curvature| / max_turn in curves; frame k sits where k are counted.
    curvature = np.abs(np.gradient(angle, cum))
    density = np.maximum(1.0 / spacing_m, curvature / np.radians(max_turn_deg))
    count = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(cum))])
    s = np.interp(np.arange(0.0, count[-1] + 1e-9), count, cum)
    out = np.column_stack([np.interp(s, cum, xy[:, 0]), np.interp(s, cum, xy[:, 1])])
    idx = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 1)
    return out, np.interp(s, cum, angle), labels[idx]


def render_route(graph: RoadGraph, length_m: float, spacing_m: float, rng: np.random.Generator,
                 smoothing_m: float = 4.0, lane_offset_m: float = 1.5, max_turn_deg: float = 3.0,
                 attempts: int = 50) -> CameraPath:
    """A smooth camera path of about ``length_m`` along a random walk on ``graph`` (see the module docstring)."""
    best: CameraPath | None = None
    for _ in range(attempts):
        route, froms = random_route(graph, length_m, rng)
        for i in range(1, len(route)):
            if route[i] == route[i - 1]:  # turned back at a dead end
                route, froms = route[:i], froms[:i]
                break
        if not route or float(graph.edges.length_m.iloc[route].sum()) < 2 * spacing_m:
            continue
        dense, labels = sample_route(graph, route, froms, DENSE_M)
        # Cut the walk to the requested length (it overshoots by up to one road).
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(dense, axis=0).T))])
        stop = int(np.searchsorted(cum, length_m + 3 * smoothing_m)) + 1
        xy, yaw, edge = smooth_path(dense[:stop], labels[:stop], spacing_m, smoothing_m, lane_offset_m, max_turn_deg)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        n = int(np.searchsorted(s, length_m, side="right")) if s[-1] > length_m else len(xy)
        path = CameraPath(xy[:n], yaw[:n], edge[:n].astype(np.int64), route)
        if np.max(np.abs(np.diff(path.yaw)), initial=0.0) > np.radians(2 * max_turn_deg):
            continue  # a fold the smoothing could not remove: take another walk
        if best is None or path.length_m > best.length_m:
            best = path
        if path.length_m >= length_m - spacing_m:
            break
    if best is None:
        raise InputError("render.length_m", f"no drivable route of at least {2 * spacing_m} m found on this road graph")
    return best
