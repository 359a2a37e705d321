"""Training routes through the map's sharpest turns (``drive.demonstrations.sharp_turn_share``).

Random walks rarely take a map's sharpest turns: a hairpin between two one-way roads, or a U-turn through the short
connector between the carriageways of a dual carriageway (two turns of about 90 deg some 20 m apart), are a few of
the many ways on at a node. A controller never shown one does not take one. Here:

* :func:`sharp_turns` lists every legal way through the map that turns at least :data:`SHARP_TURN_DEG` within
  :data:`SHARP_TURN_WITHIN_M`: two roads at a node, or two roads and the short road between them (one-way roads
  respected; the heading change summed with its sign, so a U-turn counts 180 deg, not 0);
* :class:`TrainingRoutes` draws a training route as :func:`topoloc.drive.routes.random_drive_route` does (called
  with a generator), or through one of those turns (:meth:`TrainingRoutes.through_turn`: a class of
  :func:`turn_class`, sharp, U-turn or more, left or right, drawn evenly, then one of its turns): a walk
  back from the turn, the turn, and a walk on from it (dead ends end a walk), its lane starting 20-50 % of the
  route's length before the turn's first node and checked as every training route's is.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from topoloc.drive.drive_route import DriveRoute
from topoloc.drive.routes import drive_route_of_walk, random_drive_route
from topoloc.graph.road_graph import RoadGraph
from topoloc.trajectory.drives import Walker

#: A way through the map that turns at least this much (degrees, either side) is a sharp turn.
SHARP_TURN_DEG = 135.0
#: ... within a short road of at most this length between two others (metres).
SHARP_TURN_WITHIN_M = 30.0
#: Metres at each end of a road over which its heading there is measured.
HEADING_M = 8.0


@dataclass(frozen=True)
class SharpTurn:
    """A legal way through a sharp turn: its roads, the node each is entered from, and its signed heading change
    (degrees, + left)."""

    edges: tuple[int, ...]
    froms: tuple[int, ...]
    turn_deg: float


def _wrap(angle: float) -> float:
    """``angle`` (radians) in (-pi, pi]."""
    return float(np.angle(np.exp(1j * angle)))


def _heading(coords: np.ndarray, at_end: bool) -> float:
    """Heading (radians) of a polyline over its first or last :data:`HEADING_M` metres."""
    seg = np.hypot(*np.diff(coords, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if at_end:
        i = int(np.searchsorted(cum, cum[-1] - HEADING_M, side="right")) - 1
        a, b = coords[max(i, 0)], coords[-1]
    else:
        i = int(np.searchsorted(cum, HEADING_M, side="left"))
        a, b = coords[0], coords[min(i, len(coords) - 1)]
    return float(np.arctan2(b[1] - a[1], b[0] - a[0]))


class _Ways:
    """The legal moves of a road graph, both ways round: from a node (road, next node), as the training walks take
    them (:class:`topoloc.trajectory.drives.Walker`), and into it (road, previous node)."""

    def __init__(self, graph: RoadGraph) -> None:
        self.out = Walker(graph).options
        self.into: dict[int, list[tuple[int, int]]] = {node: [] for node in self.out}
        for node, moves in self.out.items():
            for key, nxt in moves:
                self.into[nxt].append((key, node))
        for moves in self.into.values():
            moves.sort()  # by road: the walks back draw from them in a fixed order


def sharp_turns(graph: RoadGraph, min_turn_deg: float = SHARP_TURN_DEG,
                within_m: float = SHARP_TURN_WITHIN_M) -> list[SharpTurn]:
    """Every legal way through ``graph`` that turns at least ``min_turn_deg`` (see the module docstring), the
    two-road ones before those through a short road, each once."""
    ways = _Ways(graph)
    length = graph.edges.length_m.to_numpy(float)
    ends: dict[tuple[int, int], tuple[float, float]] = {}

    def headings(key: int, start: int) -> tuple[float, float]:  # (at its start, at its end) driven from ``start``
        if (key, start) not in ends:
            coords = graph.edge_coords(key, start)
            ends[(key, start)] = (_heading(coords, False), _heading(coords, True))
        return ends[(key, start)]

    def bend(a: int, a_from: int, b: int, node: int) -> float:  # at ``node``, from a's last metres to b's first
        return _wrap(headings(b, node)[0] - headings(a, a_from)[1])

    found: list[SharpTurn] = []
    longer: list[SharpTurn] = []
    limit = np.radians(min_turn_deg)
    for a_from in ways.out:
        for a, node in ways.out[a_from]:
            for b, b_end in ways.out[node]:
                if b == a:
                    continue
                turn = bend(a, a_from, b, node)
                if abs(turn) >= limit:
                    found.append(SharpTurn((a, b), (a_from, node), float(np.degrees(turn))))
                    continue
                if length[b] > within_m:
                    continue
                inner = _wrap(headings(b, node)[1] - headings(b, node)[0])  # b's own bend
                for c, _ in ways.out[b_end]:
                    if c in (a, b):
                        continue
                    total = turn + inner + bend(b, node, c, b_end)
                    if abs(total) >= limit:
                        longer.append(SharpTurn((a, b, c), (a_from, node, b_end), float(np.degrees(total))))
    return found + longer


#: Classes of sharp turns by how far they turn (degrees): sharp, a U-turn, more (round a small loop).
TURN_CLASS_DEG = (160.0, 200.0)


def turn_class(turn_deg: float) -> tuple[int, bool]:
    """The class of a sharp turn (:data:`TURN_CLASS_DEG`: 0 sharp, 1 U-turn, 2 more) and whether it turns left: a
    route is drawn through each class alike, so the many small loops of a car park do not crowd out a dual
    carriageway's few U-turns."""
    return int(np.searchsorted(TURN_CLASS_DEG, abs(turn_deg))), bool(turn_deg > 0)


def _walk(ways: dict[int, list[tuple[int, int]]], node: int, last: int, length_m: float, lengths: np.ndarray,
          rng: np.random.Generator) -> tuple[list[int], list[int]]:
    """A random walk from ``node`` over ``ways`` (roads out of a node, or into it for a walk backwards) of at least
    ``length_m`` unless a dead end stops it, never straight back along ``last``: roads and the node each leaves."""
    edges: list[int] = []
    nodes: list[int] = []
    total = 0.0
    while total < length_m:
        options = [(k, n) for k, n in ways[node] if k != (edges[-1] if edges else last)]
        if not options:
            break
        key, nxt = options[int(rng.integers(len(options)))]
        edges.append(key)
        nodes.append(node)
        total += float(lengths[key])
        node = nxt
    return edges, nodes


class TrainingRoutes:
    """The training routes of one map and route length: called with a generator, a random walk
    (:func:`topoloc.drive.routes.random_drive_route`); :meth:`through_turn`, a route through a sharp turn."""

    def __init__(self, graph: RoadGraph, conf: dict[str, Any], length_m: float) -> None:
        self.graph, self.conf, self.length_m = graph, conf, float(length_m)

    def __call__(self, rng: np.random.Generator) -> DriveRoute | None:
        return random_drive_route(self.graph, self.conf, self.length_m, rng)

    @cached_property
    def turns(self) -> list[SharpTurn]:
        """The map's sharp turns (:func:`sharp_turns`)."""
        return sharp_turns(self.graph)

    @cached_property
    def _ways(self) -> _Ways:
        return _Ways(self.graph)

    @cached_property
    def _classes(self) -> list[list[SharpTurn]]:
        groups: dict[tuple[int, bool], list[SharpTurn]] = {}
        for turn in self.turns:
            groups.setdefault(turn_class(turn.turn_deg), []).append(turn)
        return [groups[key] for key in sorted(groups)]

    def through_turn(self, rng: np.random.Generator) -> DriveRoute | None:
        """A route through one of the map's sharp turns: a class of :func:`turn_class` drawn evenly among those the
        map has, then one of its turns; None where the map has none, or the drawn one gives no drivable route (as
        :func:`topoloc.drive.routes.random_drive_route`)."""
        if not self.turns:
            return None
        group = self._classes[int(rng.integers(len(self._classes)))]
        turn = group[int(rng.integers(len(group)))]
        lengths = self.graph.edges.length_m.to_numpy(float)
        before_m = float(rng.uniform(0.2, 0.5)) * self.length_m
        back, back_to = _walk(self._ways.into, turn.froms[0], turn.edges[0], before_m, lengths, rng)
        exit_node = self.graph.other_end(turn.edges[-1], turn.froms[-1])
        after_m = self.length_m - float(lengths[back].sum()) - float(lengths[list(turn.edges)].sum())
        on, on_from = _walk(self._ways.out, exit_node, turn.edges[-1], max(after_m, 0.0), lengths, rng)
        # walking back, each road is left towards the node it was reached from: driven forwards, it is entered there
        edges = back[::-1] + list(turn.edges) + on
        froms = [self.graph.other_end(k, n) for k, n in zip(back[::-1], back_to[::-1])] + list(turn.froms) + on_from
        return drive_route_of_walk(self.graph, self.conf, edges, froms, self.length_m, lead=(turn.edges[1], before_m))
