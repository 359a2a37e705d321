"""From OSM ways to a topological road graph: nodes are intersections and dead ends.

Ways are cut into node-to-node segments; a node is kept when its number of
distinct neighbours is not two (an intersection or a dead end), or when the
traffic direction changes there (a one-way stretch meets a two-way one), as in
osmnx's simplification, so every road has one direction rule. The chains of
segments between kept nodes become the graph's roads, with the OSM nodes they
pass through, so the geometry is exact. Closed chains with no kept node (an
isolated ring road) keep their smallest node id.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from topoloc.osm.reader import DRIVABLE_HIGHWAY_CLASSES, RawNetwork


@dataclass(frozen=True)
class Road:
    """One road between two kept nodes, oriented so that ``nodes`` is canonical (see :func:`canonical`).

    ``oneway`` is +1 (travel only from ``nodes[0]`` to ``nodes[-1]``), -1 (only
    backwards) or 0 (both ways). ``lanes`` and ``width_m``: the tags of most of its tagged segments' ways (NaN
    where none is tagged).
    """

    nodes: tuple[int, ...]
    highway: str
    name: str
    oneway: int
    osm_way_ids: tuple[int, ...]
    lanes: float = float("nan")
    width_m: float = float("nan")


def canonical(nodes: tuple[int, ...]) -> tuple[tuple[int, ...], bool]:
    """Orientation-free key of a node chain and whether it was reversed to get it.

    The chain runs from its smaller end node id; a loop (same ends) is taken in
    the lexicographically smaller direction.
    """
    reverse = tuple(reversed(nodes))
    if nodes[0] != nodes[-1]:
        return (reverse, True) if nodes[0] > nodes[-1] else (nodes, False)
    return (reverse, True) if reverse < nodes else (nodes, False)


def topological_roads(network: RawNetwork) -> list[Road]:
    """Merge the network's segments into roads between intersections and dead ends, sorted canonically."""
    # segment (a, b) with a < b -> (way index, way runs a->b)
    segments: dict[tuple[int, int], tuple[int, bool]] = {}
    neighbours: dict[int, set[int]] = {}
    for index, way in enumerate(network.ways):
        for a, b in zip(way.refs[:-1], way.refs[1:]):
            if a == b:
                continue
            key = (a, b) if a < b else (b, a)
            if key in segments:
                continue  # two ways mapped over the same stretch: one road
            segments[key] = (index, a < b)
            neighbours.setdefault(a, set()).add(b)
            neighbours.setdefault(b, set()).add(a)
    kept = {node for node, nbrs in neighbours.items() if len(nbrs) != 2 or _direction_changes(node, nbrs, segments, network)}
    used: set[tuple[int, int]] = set()
    roads: list[Road] = []

    def trace(start: int, first: int) -> None:
        chain = [start, first]
        used.add(_key(start, first))
        while chain[-1] not in kept and chain[-1] != start:
            prev, cur = chain[-2], chain[-1]
            nxt = next(n for n in sorted(neighbours[cur]) if n != prev)
            if _key(cur, nxt) in used:
                break
            used.add(_key(cur, nxt))
            chain.append(nxt)
        roads.append(_road(tuple(chain), segments, network))

    for start in sorted(kept):
        for first in sorted(neighbours[start]):
            if _key(start, first) not in used:
                trace(start, first)
    for a, b in sorted(segments):
        if (a, b) not in used:  # a ring with no intersection on it
            kept.add(a)
            trace(a, b)
    return sorted(roads, key=lambda road: road.nodes)


def _allowed(a: int, b: int, segments: dict[tuple[int, int], tuple[int, bool]], network: RawNetwork) -> tuple[bool, bool]:
    """Whether segment a-b may be driven (a -> b, b -> a)."""
    index, way_runs_low_to_high = segments[_key(a, b)]
    allowed = {0: (True, True), 1: (True, False), -1: (False, True)}[network.ways[index].oneway]
    return allowed if way_runs_low_to_high == (a < b) else allowed[::-1]


def _direction_changes(node: int, nbrs: set[int], segments: dict[tuple[int, int], tuple[int, bool]], network: RawNetwork) -> bool:
    before, after = sorted(nbrs)
    return _allowed(before, node, segments, network) != _allowed(node, after, segments, network)


def _key(a: int, b: int) -> tuple[int, int]:
    return (a, b) if a < b else (b, a)


def _road(chain: tuple[int, ...], segments: dict[tuple[int, int], tuple[int, bool]], network: RawNetwork) -> Road:
    nodes, _ = canonical(chain)
    forward = backward = True
    classes: Counter[str] = Counter()
    lanes: Counter[float] = Counter()
    widths: Counter[float] = Counter()
    names: list[str] = []
    way_ids: list[int] = []
    for a, b in zip(nodes[:-1], nodes[1:]):
        way = network.ways[segments[_key(a, b)][0]]
        fwd, bwd = _allowed(a, b, segments, network)
        forward &= fwd
        backward &= bwd
        classes[way.highway] += 1
        lanes.update([way.lanes] if way.lanes == way.lanes else [])  # NaN != NaN: untagged
        widths.update([way.width_m] if way.width_m == way.width_m else [])
        if way.name and way.name not in names:
            names.append(way.name)
        if way.osm_id not in way_ids:
            way_ids.append(way.osm_id)
    rank = {cls: i for i, cls in enumerate(DRIVABLE_HIGHWAY_CLASSES)}
    highway = min(classes, key=lambda cls: (-classes[cls], rank.get(cls, len(rank)), cls))
    oneway = 1 if forward and not backward else -1 if backward and not forward else 0
    return Road(nodes, highway, ";".join(names), oneway, tuple(way_ids), _most(lanes), _most(widths))


def _most(counts: Counter[float]) -> float:
    """The most common value (the smallest of a tie), NaN of none."""
    return min(counts, key=lambda value: (-counts[value], value)) if counts else float("nan")
