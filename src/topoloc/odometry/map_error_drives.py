"""Drives on the true network of a :class:`~topoloc.odometry.map_errors.MapPair`, and their ground truth on the map.

Public functions: :func:`drive` (one drive of a pattern on the pair's truth, a
:class:`~topoloc.odometry.simulate.SimulatedDrive`) and :func:`map_truth` (the ground truth on the map a localizer
sees: per frame the map road and position, or off-map); :func:`off_map_loop` (a drive that leaves the map for a
loop and rejoins it).

Patterns (:data:`PATTERNS`), driven like :func:`topoloc.odometry.simulate.simulate_pattern_drive` (corners rounded by
:func:`topoloc.motion.route.smooth_path`, frames about a metre apart) in a lane ``lane_offset_m`` right of the
centreline, with corners smoothed over ``turn_smoothing_m``, each drawn per drive from the pair's range; walks respect
one-way roads and take the pair's missing roads (detours) whenever they pass one:

* ``random``: a random walk (no U-turn except at dead ends);
* ``out_and_back``: out, a U-turn, back to the start, a U-turn, out again (on two-way roads; the U-turn is a half
  circle across the road); where the truth has a dual carriageway: out on one carriageway, through the median
  opening at its end, back on the other, through the opening at its start, out again: the *mirror walk*, which the
  same loop driven the other way round explains equally well;
* ``circle_block``: a block circled twice (always the sharpest right turn, 120-1200 m around);
* ``long_straight``: the straightest continuation at every node (turns below 30 degrees, also within a road), the
  longest of 30 tries.

Ground truth on the map (:func:`map_truth`): a frame on true road ``e`` is on the map road, among those ``e`` is
mapped as (``MapPair.truth_to_map``), nearest to the true position whose direction of travel (one-way roads
respected) is within ``angle_tol_deg`` of the true heading (else the nearest); its position is the true position
projected onto that road. A frame on a true road the map lacks is *off-map* (road -1, the true position kept).
"""

from __future__ import annotations

import numpy as np
import shapely
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.noise import OdometryNoise, integrate_odometry
from topoloc.motion.route import DENSE_M, sample_route, smooth_path
from topoloc.odometry.map_edits import inner_turn
from topoloc.odometry.map_errors import MapPair
from topoloc.odometry.simulate import NoiseLevel, SimulatedDrive

PATTERNS = ("random", "out_and_back", "circle_block", "long_straight")
MAX_TURN_DEG = 3.0


def _heading(graph: RoadGraph, e: int, node: int, leaving: bool) -> float:
    c = graph.edge_coords(e, node) if leaving else graph.edge_coords(e, graph.other_end(e, node))
    d = c[1] - c[0] if leaving else c[-1] - c[-2]
    return float(np.arctan2(d[1], d[0]))


def _options(graph: RoadGraph, node: int, came: int | None) -> list[int]:
    """Roads that may be taken from ``node`` (one-way respected), not back along ``came`` unless at a dead end."""
    edges = graph.edges
    out = []
    for _, _, key in graph.graph.edges(node, keys=True):
        ow = edges.oneway.iat[key]
        if ow == 1 and edges.u.iat[key] != node or ow == -1 and edges.v.iat[key] != node:
            continue
        if key == came and edges.u.iat[key] != edges.v.iat[key]:
            continue
        out.append(int(key))
    return out


def _turn(graph: RoadGraph, came: int, node: int, nxt: int) -> float:
    """Signed turn (radians, left positive) from road ``came`` into ``nxt`` at ``node``."""
    return float((_heading(graph, nxt, node, True) - _heading(graph, came, node, False) + np.pi) % (2 * np.pi) - np.pi)


def walk(graph: RoadGraph, length_m: float, rng: np.random.Generator, rule: str = "random",
         prefer: set[int] | None = None, start: tuple[int, int] | None = None, max_turn_deg: float = 30.0
         ) -> tuple[list[int], list[int]]:
    """A walk of roads (and the node each is entered from) of at least ``length_m``, or until it cannot go on:
    ``rule`` ``random`` (unused ``prefer`` roads first), ``straight`` (the smallest turn, stops at turns above
    ``max_turn_deg``) or ``right`` (the sharpest right turn). ``start``: the first (road, node entered from)."""
    prefer = set(prefer or ())
    if start is None:
        e = int(rng.integers(graph.num_edges))
        ow = graph.edges.oneway.iat[e]
        node = int(graph.edges.u.iat[e] if ow == 1 or (ow == 0 and rng.random() < 0.5) else graph.edges.v.iat[e])
        start = (e, node)
    route, froms = [start[0]], [start[1]]
    total = float(graph.edges.length_m.iat[start[0]])
    node = graph.other_end(*start)
    while total < length_m and len(route) < 10000:
        options = _options(graph, node, route[-1])
        if not options:
            break
        if rule == "random":
            fresh = [o for o in options if o in prefer and o not in route]
            e = int(rng.choice(fresh or options))
        else:
            turns = {o: _turn(graph, route[-1], node, o) for o in options}
            if rule == "straight":
                e = min(turns, key=lambda o: abs(turns[o]))
                if abs(turns[e]) > np.radians(max_turn_deg) or inner_turn(graph.geometry[e]) > np.radians(max_turn_deg):
                    break
            else:
                e = min(turns, key=turns.get)
        route.append(e)
        froms.append(node)
        total += float(graph.edges.length_m.iat[e])
        node = graph.other_end(e, node)
    return route, froms


def _path(graph: RoadGraph, route: list[int], froms: list[int], offset: float, smoothing: float):
    dense, labels = sample_route(graph, route, froms, DENSE_M)
    return smooth_path(dense, labels, 1.0, smoothing, offset, MAX_TURN_DEG)


def _u_turn(end: NDArray, heading: float, offset: float, edge: int):
    """A half circle to the left of radius ``offset`` about ``end`` from the lane going ``heading`` to the lane back."""
    count = max(2, int(np.ceil(180.0 / MAX_TURN_DEG)))
    a = heading - np.pi / 2 + np.linspace(0.0, np.pi, count + 1)[1:-1]
    xy = end + offset * np.column_stack([np.cos(a), np.sin(a)])
    return xy, a + np.pi / 2, np.full(len(a), edge)


def _out_and_back(pair: MapPair, length_m: float, offset: float, smoothing: float, rng: np.random.Generator):
    graph = pair.truth
    if pair.dual:
        right, left, openings = pair.dual[int(rng.integers(len(pair.dual)))]
        rnodes = [int(graph.edges.u.iat[e]) for e in right]
        lap_route = right + [openings[-1]] + left[::-1] + [openings[0]]
        lap_froms = rnodes + [int(graph.edges.v.iat[right[-1]])] + [int(graph.edges.u.iat[e]) for e in left[::-1]] \
            + [int(graph.edges.v.iat[left[0]])]
        lap = float(graph.edges.length_m.iloc[lap_route].sum())
        laps = int(np.ceil(length_m / lap)) + 1
        route, froms = lap_route * laps + right, lap_froms * laps + rnodes
        return (*_path(graph, route, froms, offset, smoothing), route)
    best: tuple[list[int], list[int]] = ([], [])
    for _ in range(20):  # on two-way roads only (it drives back along them), never back at a dead end
        route, froms = walk(graph, length_m / 3.0, rng)
        for i in range(len(route)):
            if graph.edges.oneway.iat[route[i]] != 0 or i and route[i] == route[i - 1]:
                route, froms = route[:i], froms[:i]
                break
        if sum(graph.edges.length_m.iat[e] for e in route) > sum(graph.edges.length_m.iat[e] for e in best[0]):
            best = (route, froms)
        if sum(graph.edges.length_m.iat[e] for e in route) >= 0.8 * length_m / 3.0:
            break
    route, froms = best
    if not route:
        raise ValueError("out_and_back: no two-way road to drive out and back on")
    back_froms = [graph.other_end(e, f) for e, f in zip(route, froms)][::-1]
    legs = [(route, froms), (route[::-1], back_froms)]
    xy, yaw, edge = [], [], []
    for k in range(3 + int(length_m // max(1.0, 3.0 * float(graph.edges.length_m.iloc[route].sum())))):
        r, f = legs[k % 2]
        leg_xy, leg_yaw, leg_edge = _path(graph, r, f, offset, smoothing)
        xy.append(leg_xy)
        yaw.append(leg_yaw)
        edge.append(leg_edge)
        end = graph.edge_coords(r[-1], f[-1])[-1]
        arc = _u_turn(end, float(leg_yaw[-1]), offset, r[-1])
        xy.append(arc[0])
        yaw.append(arc[1])
        edge.append(arc[2])
    yaw = [np.unwrap(np.concatenate([np.atleast_1d(y) for y in yaw]))]
    return np.concatenate(xy), yaw[0], np.concatenate(edge), route


def _circle_block(graph: RoadGraph, rng: np.random.Generator, tries: int = 200):
    for _ in range(tries):
        route, froms = walk(graph, 1300.0, rng, rule="right")
        for j in range(1, len(route)):
            if route[j] == route[0] and froms[j] == froms[0]:
                loop = float(graph.edges.length_m.iloc[route[:j]].sum())
                if 120.0 <= loop <= 1200.0 and len(set(route[:j])) == j:
                    return route[:j] * 2 + route[:1], froms[:j] * 2 + froms[:1]
                break
    return None


def drive(pair: MapPair, pattern: str, length_m: float, level: NoiseLevel, rng: np.random.Generator) -> SimulatedDrive:
    """One drive of ``pattern`` (module docstring) of about ``length_m`` on ``pair.truth``, noise drawn from ``level``."""
    if pattern not in PATTERNS:
        raise ValueError(f"pattern must be one of {PATTERNS}, got {pattern!r}")
    graph = pair.truth
    offset = float(rng.uniform(*pair.lane_offset_m))
    low, high = pair.turn_smoothing_m  # drawn only where it varies: the other types' drives stay as they were
    smoothing = float(rng.uniform(low, high)) if high > low else float(low)
    if pattern == "out_and_back":
        xy, yaw, edge, route = _out_and_back(pair, length_m, offset, smoothing, rng)
    else:
        found = _circle_block(graph, rng) if pattern == "circle_block" else None
        if found is None and pattern == "long_straight":
            straight = [e for e in range(graph.num_edges) if inner_turn(graph.geometry[e]) < np.radians(30.0)]
            starts = [(int(e), int(graph.edges.u.iat[e] if graph.edges.oneway.iat[e] >= 0 else graph.edges.v.iat[e]))
                      for e in rng.choice(straight, 30)]
            found = max((walk(graph, length_m + 20.0, rng, rule="straight", start=s) for s in starts),
                        key=lambda w: float(graph.edges.length_m.iloc[w[0]].sum()))
        if found is None:
            found = max((walk(graph, length_m + 20.0, rng, prefer=pair.detours) for _ in range(5)),
                        key=lambda w: float(graph.edges.length_m.iloc[w[0]].sum()))
            for i in range(1, len(found[0])):
                if found[0][i] == found[0][i - 1]:
                    found = (found[0][:i], found[1][:i])
                    break
        route = found[0]
        xy, yaw, edge = _path(graph, *found, offset, smoothing)
    if pattern != "circle_block":
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        keep = cum <= length_m
        xy, yaw, edge = xy[keep], yaw[keep], edge[keep]
    noise = level.draw(rng)
    odometry = integrate_odometry(xy, yaw, OdometryNoise.from_dict(noise), rng)
    return SimulatedDrive(xy, yaw, np.asarray(edge, np.int64), odometry, noise, pattern, list(route))


def _project(coords: NDArray, xy: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Distance of each point of ``xy`` to the polyline, the projected point and the polyline's heading there."""
    line = shapely.LineString(coords)
    along = shapely.line_locate_point(line, shapely.points(xy))
    point = shapely.get_coordinates(shapely.line_interpolate_point(line, along))
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
    seg = np.clip(np.searchsorted(cum, along, side="right") - 1, 0, len(coords) - 2)
    d = coords[seg + 1] - coords[seg]
    return np.hypot(*(point - xy).T), point, np.arctan2(d[:, 1], d[:, 0])


def map_truth(pair: MapPair, edge: NDArray[np.int64], xy: NDArray[np.float64], yaw: NDArray[np.float64],
              angle_tol_deg: float = 60.0) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Per frame the map road (-1 off-map) and the map position the true ``edge``, ``xy``, ``yaw`` correspond to
    (module docstring)."""
    edge = np.asarray(edge, np.int64)
    xy = np.asarray(xy, float)
    out_edge = np.full(len(edge), -1, np.int64)
    out_xy = xy.copy()
    tol = np.radians(angle_tol_deg)
    for e in np.unique(edge):
        idx = np.flatnonzero(edge == e)
        candidates = pair.truth_to_map.get(int(e), [])
        if not candidates:
            continue
        best = np.full(len(idx), np.inf)
        for m in candidates:
            dist, point, heading = _project(pair.map.geometry[m], xy[idx])
            ow = int(pair.map.edges.oneway.iat[m])
            diff = np.abs((yaw[idx] - heading + np.pi) % (2 * np.pi) - np.pi)
            ok = diff <= tol if ow == 1 else (np.pi - diff <= tol if ow == -1 else np.ones(len(idx), bool))
            score = dist + np.where(ok, 0.0, 1e6)
            better = score < best
            best[better] = score[better]
            out_edge[idx[better]] = m
            out_xy[idx[better]] = point[better]
    return out_edge, out_xy


def off_map_loop(xy: NDArray[np.float64], yaw: NDArray[np.float64], edge: NDArray[np.int64], at_m: float,
                 back_m: float = 60.0, out_m: float = 30.0
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], int]:
    """A drive (frames ``xy``, ``yaw``, true road ``edge``) with a loop off the map inserted (a parking lot the map
    lacks): from the frame at ``at_m`` metres out ``out_m`` to the right, back parallel to the road, and onto it
    again ``back_m`` earlier, which is then driven again; corners rounded. Frames off the map get road -1.
    Returns xy, yaw, edge and the first frame back on the road."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    k, j = int(np.searchsorted(cum, at_m)), int(np.searchsorted(cum, at_m - back_m))
    h = np.arctan2(*(xy[k] - xy[j])[::-1])
    right = np.array([np.sin(h), -np.cos(h)])
    corners = [xy[k], xy[k] + right * out_m, xy[j] + right * out_m, xy[j]]
    pts = [corners[0]]
    for a, b in zip(corners[:-1], corners[1:]):
        n = max(1, int(np.hypot(*(b - a))))
        pts += list(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    pts = np.asarray(pts)
    for _ in range(3):  # rounded corners
        pts[1:-1] = (pts[:-2] + pts[1:-1] + pts[2:]) / 3.0
    loop_yaw = np.arctan2(*np.diff(pts, axis=0).T[::-1])[1:]
    loop = pts[1:-1]
    out_xy = np.concatenate([xy[:k + 1], loop, xy[j:]])
    out_yaw = np.unwrap(np.concatenate([yaw[:k + 1], loop_yaw, yaw[j:]]))
    out_edge = np.concatenate([edge[:k + 1], np.full(len(loop), -1), edge[j:]])
    return out_xy, out_yaw, out_edge, k + 1 + len(loop)
