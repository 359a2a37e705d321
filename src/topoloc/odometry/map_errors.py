"""Map errors for the simulated benchmark: a true road network and the map a localizer sees, by error type and level.

Public functions: :func:`make_map_pair` (a :class:`MapPair` of one error type and level from a true network),
:func:`dual_carriageway_grid` (a synthetic map with dual carriageways, for the mirror walk), :func:`split_dual`
(a chain of two-way roads made a dual carriageway, in :mod:`topoloc.odometry.map_edits` with the other edits). The
drives on the truth (:func:`topoloc.odometry.map_error_drives.drive`: random, out-and-back / mirror walk, a block
circled twice, a long straight) and their ground truth on the map (:func:`topoloc.odometry.map_error_drives.map_truth`)
are in :mod:`topoloc.odometry.map_error_drives`.

Error types (:data:`ERROR_TYPES`) and what a level sets (:data:`LEVELS`; ``none`` is the map equal to the truth):

* ``lateral``: the map is the truth; the drive keeps to a lane ``lane_offset_m`` right of the centreline (both
  directions), drawn per drive (the other types drive 1.5 m right of it, as :mod:`topoloc.odometry.simulate`).
* ``displacement``: every node is moved by up to ``node_m`` (uniform direction and magnitude) between map and
  truth, the geometry between follows linearly, and every road gets a bend of up to ``curve_m`` (a half sine
  between its ends).
* ``simplified``: the map's geometry is the truth's simplified by Douglas-Peucker at ``tolerance_m``; truth roads
  that are straight (two points, >= 40 m) get an S-bend of 0.5-1 tolerance first, so there is something to
  simplify.
* ``dual_as_one``: the truth has ``share`` of its straight chains of two-way roads as dual carriageways (two one-way
  roads ``gap_m`` apart, a median opening at every node), the map has them as one two-way road.
* ``two_way_as_dual``: the reverse: the truth has one two-way road, the map two one-way roads ``gap_m`` apart.
* ``missing_road``: the truth has parking lot / service road loops (off ``share`` of the roads, ``depth_m`` deep)
  that the map lacks; drives take them (:func:`topoloc.odometry.map_error_drives.drive`).
* ``extra_road``: the map has roads (``share`` of them, never a bridge of the truth) that the truth lacks.
* ``wide_turns``: the map is the truth; the drive rounds its corners more widely, smoothed over ``turn_smoothing_m``
  (drawn per drive; the other types smooth over 4 m: about a 9 m radius at a right angle, KITTI 00's turns; KITTI
  02's and 10's take 15-17 m), so it drives metres less through a junction than the map's path through the node.

A :class:`MapPair` keeps, per true road, the map roads it corresponds to (``truth_to_map``; empty where the map
lacks it), which the ground truth on the map uses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from topoloc.graph.road_graph import EDGE_COLUMNS, RoadGraph
from topoloc.odometry.map_edits import (add_detours, build_graph, copy_graph, curvy, displace, drop_roads, simplify,
                                        split_dual, straight_chains)

ERROR_TYPES = ("lateral", "displacement", "simplified", "dual_as_one", "two_way_as_dual", "missing_road", "extra_road",
               "wide_turns")
LEVEL_NAMES = ("none", "low", "medium", "high")

#: Per error type and level (low, medium, high) its parameters; ``none`` is always the map equal to the truth.
LEVELS: dict[str, dict[str, dict[str, Any]]] = {
    "lateral": {"low": {"lane_offset_m": (1.5, 3.0)}, "medium": {"lane_offset_m": (3.0, 6.0)},
                "high": {"lane_offset_m": (6.0, 10.0)}},
    "displacement": {"low": {"node_m": 2.0, "curve_m": 1.0}, "medium": {"node_m": 5.0, "curve_m": 3.0},
                     "high": {"node_m": 10.0, "curve_m": 6.0}},
    "simplified": {"low": {"tolerance_m": 1.0}, "medium": {"tolerance_m": 3.0}, "high": {"tolerance_m": 6.0}},
    "dual_as_one": {"low": {"share": 0.1, "gap_m": (15.0, 20.0)}, "medium": {"share": 0.25, "gap_m": (15.0, 20.0)},
                    "high": {"share": 0.5, "gap_m": (15.0, 20.0)}},
    "two_way_as_dual": {"low": {"share": 0.1, "gap_m": (15.0, 20.0)}, "medium": {"share": 0.25, "gap_m": (15.0, 20.0)},
                        "high": {"share": 0.5, "gap_m": (15.0, 20.0)}},
    "missing_road": {"low": {"share": 0.02, "depth_m": (25.0, 45.0)}, "medium": {"share": 0.05, "depth_m": (25.0, 45.0)},
                     "high": {"share": 0.15, "depth_m": (25.0, 45.0)}},
    "extra_road": {"low": {"share": 0.03}, "medium": {"share": 0.08}, "high": {"share": 0.15}},
    # smoothing 4 / 7 / 13 / 21 m: a right angle on a radius of about 9 / 11 / 18 / 27 m
    "wide_turns": {"low": {"turn_smoothing_m": (4.0, 7.0)}, "medium": {"turn_smoothing_m": (7.0, 13.0)},
                   "high": {"turn_smoothing_m": (13.0, 21.0)}},
}

DEFAULT_LANE_OFFSET_M = 1.5
DEFAULT_TURN_SMOOTHING_M = 4.0


@dataclass
class MapPair:
    """A true road network, the map a localizer sees, and how they correspond.

    ``truth_to_map[e]``: the map roads true road ``e`` is mapped as (empty: the map lacks it). ``lane_offset_m``:
    the range the drive's lane offset is drawn from, ``turn_smoothing_m`` that of its corners' smoothing. ``dual``:
    the dual carriageways of the truth, each ``(right, left, openings)`` lists of true edge ids (``right`` one-way
    forward along the chain, ``left`` back, ``openings`` the median openings at the chain's nodes in chain order). ``detours``: the true edges of the
    missing roads (the drive prefers them)."""

    truth: RoadGraph
    map: RoadGraph
    error: str
    level: str
    truth_to_map: dict[int, list[int]]
    lane_offset_m: tuple[float, float] = (DEFAULT_LANE_OFFSET_M, DEFAULT_LANE_OFFSET_M)
    turn_smoothing_m: tuple[float, float] = (DEFAULT_TURN_SMOOTHING_M, DEFAULT_TURN_SMOOTHING_M)
    dual: list[tuple[list[int], list[int], list[int]]] = field(default_factory=list)
    detours: set[int] = field(default_factory=set)


def _pick_chains(graph: RoadGraph, share: float, rng: np.random.Generator) -> list[list[tuple[int, int]]]:
    """Straight chains covering about ``share`` of the road length (at least one), disjoint in nodes."""
    chains = straight_chains(graph)
    order = rng.permutation(len(chains))
    total = float(graph.edges.length_m.sum())
    picked, covered, nodes_used = [], 0.0, set()
    for i in order:
        chain = chains[i]
        nodes = {f for _, f in chain} | {graph.other_end(*chain[-1])}
        if nodes & nodes_used:
            continue
        picked.append(chain)
        nodes_used |= nodes
        covered += float(graph.edges.length_m.iloc[[e for e, _ in chain]].sum())
        if covered >= share * total:
            break
    return picked


def _draw(value: Any, rng: np.random.Generator, n: int | None = None) -> Any:
    return rng.uniform(*value, n) if isinstance(value, tuple) else value


def _identity(graph: RoadGraph) -> dict[int, list[int]]:
    return {e: [e] for e in range(graph.num_edges)}


def make_map_pair(base: RoadGraph, error: str, level: str, rng: np.random.Generator,
                  dual: list[tuple[list[int], list[int], list[int]]] | None = None) -> MapPair:
    """The (true network, map) pair of ``error`` at ``level`` made from the road network ``base`` (module docstring).

    The map is ``base`` itself (its roads, ids and a model trained on it apply) except for ``two_way_as_dual`` (the
    map is ``base`` with dual carriageways) and ``simplified`` (``base`` simplified); the truth is ``base`` made
    different (displaced, bent, with dual carriageways, detours, or roads dropped). ``dual``: the dual carriageways
    of ``base`` (:func:`dual_carriageway_grid`), kept where the truth has ``base``'s roads."""
    if error not in ERROR_TYPES:
        raise ValueError(f"error must be one of {ERROR_TYPES}, got {error!r}")
    if level not in LEVEL_NAMES:
        raise ValueError(f"level must be one of {LEVEL_NAMES}, got {level!r}")
    same = list(dual or [])
    if level == "none":
        return MapPair(base, copy_graph(base), error, level, _identity(base), dual=same)
    p = LEVELS[error][level]
    if error == "lateral":
        return MapPair(base, copy_graph(base), error, level, _identity(base), lane_offset_m=p["lane_offset_m"], dual=same)
    if error == "wide_turns":
        return MapPair(base, copy_graph(base), error, level, _identity(base), turn_smoothing_m=p["turn_smoothing_m"],
                       dual=same)
    if error == "displacement":
        return MapPair(displace(base, p["node_m"], p["curve_m"], rng), copy_graph(base), error, level, _identity(base),
                       dual=same)
    if error == "simplified":  # bends within the tolerance: a straight road of base is its own simplification
        tol = p["tolerance_m"]
        curved = curvy(base, 0.5 * tol, tol, rng)
        return MapPair(curved, simplify(curved, tol), error, level, _identity(curved), dual=same)
    if error in ("dual_as_one", "two_way_as_dual"):
        chains = _pick_chains(base, p["share"], rng)
        split, old_to_new, duals = split_dual(base, chains, _draw(p["gap_m"], rng, len(chains)))
        if error == "dual_as_one":
            back = {new: [old] for old, news in old_to_new.items() for new in news}
            for chain, (_, _, openings) in zip(chains, duals):  # an opening: the map roads at its node
                for k, opening in enumerate(openings):
                    back[opening] = [e for e, _ in chain[max(0, k - 1): k + 1]]
            to_map = {e: back.get(e, []) for e in range(split.num_edges)}
            return MapPair(split, copy_graph(base), error, level, to_map, dual=duals)
        return MapPair(base, split, error, level, old_to_new, dual=same)
    if error == "missing_road":
        richer, old_to_new, detours = add_detours(base, p["share"], p["depth_m"], rng)
        back = {new: [old] for old, news in old_to_new.items() for new in news}
        to_map = {e: back.get(e, []) for e in range(richer.num_edges)}
        return MapPair(richer, copy_graph(base), error, level, to_map, detours=detours)
    poorer, new_to_old = drop_roads(base, p["share"], rng)
    return MapPair(poorer, copy_graph(base), error, level, {new: [old] for new, old in new_to_old.items()})


def dual_carriageway_grid(like: RoadGraph | None = None, length_m: float = 600.0, gap_m: float = 17.0,
                          block_m: tuple[float, ...] = (120.0, 150.0, 90.0, 150.0, 120.0)) -> MapPair:
    """A synthetic map for the mirror walk: a dual carriageway ``gap_m`` wide along a street of blocks ``block_m``
    (summing to about ``length_m``), two-way side streets of 120 m on both sides at each inner node. With blocks
    that read the same both ways (the default) the map is symmetric under a half turn, so the loop out on one
    carriageway and back on the other is explained equally well from either end: no localizer, nor the oracle,
    can tell the two apart. The pair's map
    is its truth (error ``none``); pass its ``dual`` to :func:`make_map_pair` with its truth as the base."""
    xs = np.concatenate([[0.0], np.cumsum(block_m)])
    xs = xs * length_m / xs[-1]
    coords = {i: (float(x), 0.0) for i, x in enumerate(xs)}
    edges = [(i, i + 1) for i in range(len(xs) - 1)]
    for i in range(1, len(xs) - 1):
        coords[100 + i] = (float(xs[i]), 120.0)
        coords[200 + i] = (float(xs[i]), -120.0)
        edges += [(i, 100 + i), (i, 200 + i)]
    nodes = pd.DataFrame({"x": [c[0] for c in coords.values()], "y": [c[1] for c in coords.values()]},
                         index=pd.Index(list(coords), name="node_id"))
    records = [{"u": u, "v": v, "oneway": 0} for u, v in edges]
    geometry = [np.array([coords[u], coords[v]], float) for u, v in edges]
    template = like or RoadGraph(nodes.assign(lon=0.0, lat=0.0, degree=0), pd.DataFrame(columns=EDGE_COLUMNS), [],
                                 "EPSG:3067", 20.0)
    street = build_graph(nodes, records, geometry, template)
    chain = [(e, e) for e in range(len(xs) - 1)]  # edge i runs from node i
    dual, _, duals = split_dual(street, [chain], np.array([gap_m]))
    return MapPair(dual, copy_graph(dual), "none", "none", _identity(dual), dual=duals)
