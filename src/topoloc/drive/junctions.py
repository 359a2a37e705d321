"""The junction benchmark of the repeat drives: every junction on a route, and whether each drive took it as commanded.

* A **junction** is a node of the road graph on the route where the vehicle could go another way: besides the road
  the route comes in on, at least two roads meet there (as for the map's commands,
  :func:`topoloc.place.topometric_map.route_intersections`; a one-way road the wrong way round is still a road the
  camera shows and a controller can turn into). ``exits`` counts those a car may drive legally. Junction nodes
  closer than ``cluster_m`` along the lane (each to the next) are one junction (a dual carriageway's two crossings, a
  staggered crossroads, a roundabout's entry and exit), counted once.
* Its **turn** is the lane's heading change from ``around_m`` before its first node to ``around_m`` past its last
  (+ left): ``straight`` under 20 deg, ``slight`` under 60, ``left`` / ``right`` under 120, ``sharp`` under 160,
  else ``U-turn`` (:data:`TURNS`).
* Its **kind** (:data:`KINDS`): ``roundabout`` when one of its roads is an OSM way tagged ``junction=roundabout``
  (the road graph keeps the ways' ids, not their tags: :func:`roundabout_ways` reads them from the OSM file);
  else ``cluster`` when it spans several graph nodes; else by the node's roads: four or more a ``cross``, three a
  ``T`` when two of them run on in one line (within 25 deg) and the third leaves them at 60 deg or more, else a
  ``fork``.
* A drive **took** a junction when it got ``after_m`` past its last node (or finished); it **failed** it when it
  ended (off road, on a wrong road, reversed, timed out) from ``before_m`` before its first node to ``after_m`` past
  its last; junctions it did not reach are left out of the rates (:func:`junction_results`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import osmium
import pandas as pd
from numpy.typing import NDArray

from topoloc.drive.drive_route import DriveRoute
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.place.topometric_map import COMMANDS

#: Turn classes, by the absolute heading change (deg) they end below, then their side.
TURNS = ("straight", "slight left", "slight right", "left", "right", "sharp left", "sharp right", "U-turn")
_TURN_LIMITS = ((20.0, "straight"), (60.0, "slight"), (120.0, ""), (160.0, "sharp"))
#: Junction kinds.
KINDS = ("T", "cross", "fork", "roundabout", "cluster")
#: The results of a drive at a junction.
TAKEN, FAILED, NOT_REACHED = "taken", "failed", "not reached"
_BRANCH_M = 10.0  # how far along a road its direction at a node is measured


@dataclass(frozen=True)
class Junction:
    """A junction of a route: its graph nodes, where the lane reaches the first and leaves the last (arc length, m),
    the lane's heading change through it (deg, + left), its turn class and kind, the roads leaving it (besides the
    one the route comes in on), the command the route gives before it (before each of its nodes in turn, joined by
    ``-`` where they differ) and the lane distance from the previous junction (from the route's start for the first)."""

    nodes: tuple[int, ...]
    entry_s: float
    exit_s: float
    angle_deg: float
    turn: str
    kind: str
    exits: int
    command: str
    gap_m: float


def classify_turn(angle_deg: float) -> str:
    """The turn class (:data:`TURNS`) of a heading change (deg, + left)."""
    size = abs(angle_deg)
    for limit, name in _TURN_LIMITS:
        if size < limit:
            if name == "straight":
                return name
            side = "left" if angle_deg > 0 else "right"
            return f"{name} {side}".strip()
    return "U-turn"


def roundabout_ways(osm_path: str | None) -> set[int]:
    """Ids of the OSM ways tagged ``junction=roundabout`` (or ``circular``) in ``osm_path`` (none without a file)."""
    if not osm_path:
        return set()
    try:
        processor = osmium.FileProcessor(str(osm_path), osmium.osm.WAY).with_filter(osmium.filter.KeyFilter("junction"))
        return {int(w.id) for w in processor if w.is_way() and w.tags.get("junction") in ("roundabout", "circular")}
    except RuntimeError as err:
        raise InputError(osm_path, f"cannot read the OSM file for its roundabouts ({err})") from err


def _leaves(graph: RoadGraph, edge: int, node: int) -> bool:
    """Whether a car may drive ``edge`` away from ``node``."""
    oneway, u, v = int(graph.edges.oneway.iat[edge]), graph.edges.u.iat[edge], graph.edges.v.iat[edge]
    return oneway == 0 or (oneway > 0 and u == node) or (oneway < 0 and v == node)


def _branches(graph: RoadGraph, node: int) -> list[tuple[int, NDArray[np.float64]]]:
    """Each road end at ``node`` (a loop twice): its edge and unit direction away from the node."""
    out = []
    here = graph.nodes.loc[node, ["x", "y"]].to_numpy(float)
    for edge in np.flatnonzero((graph.edges.u.to_numpy() == node) | (graph.edges.v.to_numpy() == node)):
        coords = graph.geometry[int(edge)]
        ends = [coords] if graph.edges.u.iat[edge] == node else []
        ends += [coords[::-1]] if graph.edges.v.iat[edge] == node else []
        for line in ends:
            cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
            at = min(_BRANCH_M, float(cum[-1]))
            point = np.array([np.interp(at, cum, line[:, 0]), np.interp(at, cum, line[:, 1])])
            d = point - here
            out.append((int(edge), d / max(float(np.hypot(*d)), 1e-9)))
    return out


def node_kind(graph: RoadGraph, node: int) -> str:
    """``cross``, ``T`` or ``fork`` by the roads at one node (see the module docstring)."""
    branches = _branches(graph, node)
    if len(branches) >= 4:
        return "cross"
    dirs = [d for _, d in branches]
    for i, j, k in ((0, 1, 2), (0, 2, 1), (1, 2, 0)):
        if len(dirs) == 3 and float(dirs[i] @ dirs[j]) < np.cos(np.radians(155.0)):
            if max(float(dirs[k] @ dirs[i]), float(dirs[k] @ dirs[j])) <= np.cos(np.radians(60.0)):
                return "T"
    return "fork"


def _route_nodes(graph: RoadGraph, route: DriveRoute) -> list[tuple[int, float, int, int]]:
    """The graph nodes the lane passes from one road to the next: node, arc length, the road in, the road out."""
    out = []
    for k in np.flatnonzero(np.diff(route.edge) != 0) + 1:
        e1, e2 = int(route.edge[k - 1]), int(route.edge[k])
        ends1 = {graph.edges.u.iat[e1], graph.edges.v.iat[e1]}
        shared = [n for n in (graph.edges.u.iat[e2], graph.edges.v.iat[e2]) if n in ends1]
        if not shared:
            continue
        node = min(shared, key=lambda n: float(np.hypot(*(graph.nodes.loc[n, ["x", "y"]].to_numpy(float) - route.xy[k]))))
        out.append((int(node), float(route.s[k]), e1, e2))
    return out


def route_junctions(graph: RoadGraph, route: DriveRoute, roundabouts: set[int] | None = None, cluster_m: float = 25.0,
                    around_m: float = 15.0) -> list[Junction]:
    """The junctions of ``route`` in lane order (see the module docstring); ``roundabouts``: OSM way ids
    (:func:`roundabout_ways`)."""
    roundabouts = roundabouts or set()
    way_ids = [{int(w) for w in str(ids).split(";") if w} for ids in graph.edges.osm_way_ids]
    groups: list[list[tuple[int, float, int, int]]] = []
    for node, s, e_in, e_out in _route_nodes(graph, route):
        if len(_branches(graph, node)) < 3:
            continue  # a bend or a change of road: no other way to go
        if groups and s - groups[-1][-1][1] <= cluster_m:
            groups[-1].append((node, s, e_in, e_out))
        else:
            groups.append([(node, s, e_in, e_out)])
    yaw = np.unwrap(route.yaw)
    out: list[Junction] = []
    for group in groups:
        nodes = tuple(dict.fromkeys(g[0] for g in group))
        entry, leave = group[0][1], group[-1][1]
        before, after = max(0.0, entry - around_m), min(route.length_m, leave + around_m)
        angle = float(np.degrees(np.interp(after, route.s, yaw) - np.interp(before, route.s, yaw)))
        roads = {e for n in nodes for e, _ in _branches(graph, n)}
        if any(way_ids[e] & roundabouts for e in roads):
            kind = "roundabout"
        else:
            kind = "cluster" if len(nodes) > 1 else node_kind(graph, nodes[0])
        internal = {g[2] for g in group[1:]}
        exits = len({e for n in nodes for e, _ in _branches(graph, n) if _leaves(graph, e, n)} - internal - {group[0][2]})
        command = "-".join(dict.fromkeys(COMMANDS[route.command_at(max(0.0, g[1] - 2.0))] for g in group))
        gap = entry - (out[-1].exit_s if out else 0.0)
        out.append(Junction(nodes, entry, leave, angle, classify_turn(angle), kind, exits, command, gap))
    return out


def junction_results(junctions: list[Junction], s: NDArray[np.float64], speed: NDArray[np.float64], outcome: str,
                     before_m: float = 10.0, after_m: float = 20.0) -> list[dict[str, object]]:
    """One row per junction for one drive: its progress ``s`` (lane arc length per step), ``speed`` (m/s per step)
    and ``outcome``; the result (:data:`TAKEN`, :data:`FAILED` or :data:`NOT_REACHED`, see the module docstring) and
    the speed on entry (at the first node; NaN when not reached)."""
    s = np.maximum.accumulate(np.asarray(s, float)) if len(s) else np.zeros(1)
    speed = np.asarray(speed, float) if len(speed) else np.zeros(1)
    end = float(s[-1])
    rows, blamed = [], False
    for j in junctions:
        if outcome == "success" or end >= j.exit_s + after_m:
            result = TAKEN
        elif not blamed and end >= j.entry_s - before_m:
            result, blamed = FAILED, True
        else:
            result = NOT_REACHED
        reached = end >= j.entry_s
        entry_speed = float(speed[min(int(np.searchsorted(s, j.entry_s)), len(speed) - 1)]) if reached else float("nan")
        rows.append({"junction": len(rows), "nodes": ";".join(map(str, j.nodes)), "kind": j.kind, "turn": j.turn,
                     "angle_deg": j.angle_deg, "command": j.command, "exits": j.exits, "entry_s_m": j.entry_s,
                     "gap_m": j.gap_m, "entry_speed_mps": entry_speed, "result": result,
                     "outcome": outcome if result == FAILED else ""})
    return rows


def junction_rates(rows: pd.DataFrame, by: str, order: tuple[str, ...]) -> pd.DataFrame:
    """Per agent (rows) and value of column ``by`` (columns in ``order``, those present): the share of junctions taken
    among those reached (taken or failed), and how many were reached."""
    reached = rows[rows.result != NOT_REACHED]
    grouped = reached.groupby(["agent", by], sort=False).result
    rate = (grouped.apply(lambda r: float((r == TAKEN).mean())).unstack(by))
    count = grouped.size().unstack(by)
    cols = [c for c in order if c in rate.columns]
    agents = list(dict.fromkeys(rows.agent))
    return pd.concat({"rate": rate.reindex(index=agents, columns=cols), "reached": count.reindex(index=agents, columns=cols)},
                     axis=1)
