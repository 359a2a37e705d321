"""A dual carriageway that may be one road: the map's dual pairs with a merged two-way road beside them.

A map draws a road with a median, or only a painted divider, as two one-way roads some metres apart (a *dual
carriageway*); mappers draw the same kind of road as one two-way road elsewhere. Where the map has two and the
road driven is one, every turn onto or off it is made metres from where the map puts it, and a block circled
along it is metres shorter or longer on the map than driven, lap after lap. :func:`merge_duals` gives the filter
both readings of the map: every *dual pair* (:func:`dual_pairs`: two one-way roads that run side by side in
opposite directions between two pairs of facing nodes) gets a two-way road along their middle, and each of the
pair's nodes a *link* to the middle (half the gap, two-way), so a drive onto the pair from a side road may go on
to the middle road as it would onto a single two-way road (:func:`merged_moves`: a link leads from the middle road to
the roads at the pair's node but the pair's own, so it is no way across the median nor a U-turn that pays no
U-turn's weight). The map's own roads keep their ids; a cell of a
merged road answers as the carriageway that runs its way, a cell of a link as the carriageway at its node
(:attr:`MergedDuals.origin`), so the filter's answers name only the map's roads.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.connectivity import DirectedEdges
from topoloc.odometry.map_edits import build_graph, records_of

#: Closest the two carriageways of a pair may be (metres): nodes nearer than this are one junction, not a gap.
MIN_GAP_M = 2.0
#: Shortest road of a pair (metres): shorter one-way roads that face each other are the arcs of a roundabout.
MIN_PAIR_LENGTH_M = 30.0
#: How far the two roads of a pair may differ in length (ratio) and in heading along them (degrees).
MAX_LENGTH_RATIO = 1.35
MAX_HEADING_DEG = 30.0
LINK_NAME = "link to a merged dual carriageway"
#: Metres between the points at which a pair's two roads are compared and averaged.
SAMPLE_M = 5.0


@dataclass(frozen=True)
class MergedDuals:
    """The map with its dual pairs' merged roads and links (``graph``: the map's edges first, ids unchanged),
    ``origin``: per directed state of ``graph`` (``2 e`` runs u -> v) the map's edge it answers as, ``added``: per
    edge of ``graph`` whether it is a merged road or a link, ``link``: whether a link, ``pairs``: the dual pairs
    ``(a, b)`` merged."""

    graph: RoadGraph
    origin: NDArray[np.int64]
    added: NDArray[np.bool_]
    link: NDArray[np.bool_]
    pairs: list[tuple[int, int]]


def _directed_ends(graph: RoadGraph) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    """Per edge the node it leaves and the node it reaches in its one direction, and whether it is one-way."""
    u, v = graph.edges.u.to_numpy(np.int64), graph.edges.v.to_numpy(np.int64)
    oneway = graph.edges.oneway.to_numpy(np.int64)
    back = oneway < 0
    return np.where(back, v, u), np.where(back, u, v), oneway != 0


def _resampled(coords: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """``n`` points evenly spaced along the polyline ``coords`` (its ends included)."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
    s = np.linspace(0.0, cum[-1], n)
    return np.column_stack([np.interp(s, cum, coords[:, 0]), np.interp(s, cum, coords[:, 1])])


def _side_by_side(a: NDArray[np.float64], b: NDArray[np.float64], max_gap_m: float) -> NDArray[np.float64] | None:
    """The middle line of polylines ``a`` and ``b`` (both in the same direction) if they run side by side, at
    :data:`MIN_GAP_M` to ``max_gap_m`` apart all along, alike in length and heading; else None."""
    la, lb = (float(np.hypot(*np.diff(c, axis=0).T).sum()) for c in (a, b))
    if min(la, lb) < MIN_PAIR_LENGTH_M or max(la, lb) > MAX_LENGTH_RATIO * min(la, lb):
        return None
    n = max(3, int(np.ceil(max(la, lb) / SAMPLE_M)) + 1)
    pa, pb = _resampled(a, n), _resampled(b, n)
    gap = np.hypot(*(pa - pb).T)
    if gap.min() < MIN_GAP_M or gap.max() > max_gap_m:
        return None
    ta, tb = np.diff(pa, axis=0), np.diff(pb, axis=0)
    cos = (ta * tb).sum(axis=1) / np.maximum(np.linalg.norm(ta, axis=1) * np.linalg.norm(tb, axis=1), 1e-12)
    if cos.min() < np.cos(np.radians(MAX_HEADING_DEG)):
        return None
    return 0.5 * (pa + pb)


def dual_pairs(graph: RoadGraph, max_gap_m: float) -> list[tuple[int, int, NDArray[np.float64]]]:
    """The map's dual pairs: one-way roads ``a`` (from node p to q) and ``b`` (from r to t) with t within
    ``max_gap_m`` of p and r of q that run side by side (:func:`_side_by_side`), each road in one pair at most
    (the closest ends first); with the middle line from the p end to the q end."""
    start, end, oneway = _directed_ends(graph)
    ids = graph.nodes.index.to_numpy(np.int64)
    xy = graph.nodes[["x", "y"]].to_numpy(float)
    row = {int(n): i for i, n in enumerate(ids)}
    tree = cKDTree(xy)
    ends_at: dict[int, list[int]] = {}
    for e in np.flatnonzero(oneway):
        ends_at.setdefault(int(end[e]), []).append(int(e))
    candidates = []
    for a in np.flatnonzero(oneway):
        p, q = row[int(start[a])], row[int(end[a])]
        for t in tree.query_ball_point(xy[p], max_gap_m):
            for b in ends_at.get(int(ids[t]), []):
                r = row[int(start[b])]
                if b == a or {p, q} & {r, t}:
                    continue
                far_end = float(np.hypot(*(xy[q] - xy[r])))
                if far_end <= max_gap_m:
                    candidates.append((float(np.hypot(*(xy[p] - xy[t]))) + far_end, int(a), int(b)))
    pairs, used = [], set()
    for _, a, b in sorted(candidates):
        if a in used or b in used:
            continue
        middle = _side_by_side(graph.edge_coords(a, int(start[a])), graph.edge_coords(b, int(start[b]))[::-1], max_gap_m)
        if middle is not None:
            pairs.append((a, b, middle))
            used.update((a, b))
    return pairs


def merge_duals(graph: RoadGraph, max_gap_m: float) -> MergedDuals:
    """``graph`` with a merged two-way road along each dual pair's middle and links from the pair's nodes to it
    (the module docstring)."""
    pairs = dual_pairs(graph, max_gap_m)
    start, end, _ = _directed_ends(graph)
    nodes = graph.nodes[["x", "y", "lon", "lat"]].copy()
    records, geometry = records_of(graph), [g.copy() for g in graph.geometry]
    origin = [[e, e] for e in range(graph.num_edges)]
    merged_node: dict[tuple[int, int], int] = {}
    next_id = int(max(graph.nodes.index)) + 1

    def middle_node(n1: int, n2: int, n1_edge: int, n2_edge: int) -> int:
        nonlocal next_id
        key = (min(n1, n2), max(n1, n2))
        if key not in merged_node:
            m = merged_node[key] = next_id
            next_id += 1
            at = 0.5 * (nodes.loc[n1, ["x", "y"]].to_numpy(float) + nodes.loc[n2, ["x", "y"]].to_numpy(float))
            nodes.loc[m, ["x", "y", "lon", "lat"]] = [*at, 0.0, 0.0]
            for n, edge in ((n1, n1_edge), (n2, n2_edge)):
                records.append({"u": n, "v": m, "oneway": 0, "highway": records[edge]["highway"],
                                "name": LINK_NAME, "osm_way_ids": ""})
                geometry.append(np.array([nodes.loc[n, ["x", "y"]].to_numpy(float), at]))
                origin.append([edge, edge])
        return merged_node[key]

    for a, b, middle in pairs:
        p, q, r, t = int(start[a]), int(end[a]), int(start[b]), int(end[b])
        u, v = middle_node(p, t, a, b), middle_node(q, r, a, b)  # the middle line's ends, as computed there
        records.append({"u": u, "v": v, "oneway": 0, "highway": records[a]["highway"],
                        "name": "merged dual carriageway", "osm_way_ids": ""})
        geometry.append(middle)
        origin.append([a, b])  # u -> v runs as a, v -> u as b
    merged = build_graph(nodes, records, geometry, graph)
    added = np.arange(merged.num_edges) >= graph.num_edges
    link = added & (merged.edges.name.to_numpy() == LINK_NAME)
    return MergedDuals(merged, np.asarray(origin, np.int64).reshape(-1), added, link, [(a, b) for a, b, _ in pairs])


def merged_moves(merged: MergedDuals, states: DirectedEdges) -> DirectedEdges:
    """``states`` (of ``merged.graph``) without the moves between a link and a road of a dual pair or another link:
    from the middle road a link leads to the side roads at the pair's node, not across the median (two links) nor
    back onto a carriageway (which would turn back without a U-turn's weight), and a carriageway leads to no link.
    A link that leads nowhere then but back (a pair's node without side roads) is not entered. Only the one-hop moves
    (``next_ptr``, ``next_idx``, which the metric filter's chains follow) change, not the token ``successors``."""
    paired = np.zeros(merged.graph.num_edges, bool)
    paired[[e for pair in merged.pairs for e in pair]] = True
    link, pair = merged.link[states.edge], paired[states.edge]
    src = np.repeat(np.arange(states.num_states), np.diff(states.next_ptr))
    dst = states.next_idx
    barred = (link[src] & (link[dst] | pair[dst]) & (dst != (src ^ 1))) | (pair[src] & link[dst])
    onward = np.bincount(src[~barred & (dst != (src ^ 1))], minlength=states.num_states) > 0
    barred |= link[dst] & ~onward[dst]  # into a link with no way on but its U-turn
    counts = np.bincount(src[~barred], minlength=states.num_states)
    return replace(states, next_ptr=np.concatenate([[0], np.cumsum(counts)]), next_idx=dst[~barred])
