"""A dual carriageway that may be one road (``localization.metric.merge_duals_m``): the dual pairs found, the merged
road along their middle with links from the pair's nodes, and the metric filter on a map that draws a two-way road
as a dual carriageway."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from localization_helpers import drive_along, dual_carriageway

from topoloc.config import load
from topoloc.graph.road_graph import EDGE_COLUMNS, RoadGraph
from topoloc.localization.connectivity import directed_edges
from topoloc.localization.metric.merged_duals import dual_pairs, merge_duals, merged_moves
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.odometry.map_edits import build_graph, split_dual
from topoloc.registry import make

GAP_M = 17.0


def street_graph() -> RoadGraph:
    """A two-way street along y = 0 (nodes 0-4 at x = 0, 120, 270, 360, 510) with two-way side streets of unequal
    lengths north and south of its inner nodes (so no walk has a mirror)."""
    xs = [0.0, 120.0, 270.0, 360.0, 510.0]
    coords = {i: (x, 0.0) for i, x in enumerate(xs)}
    edges = [(i, i + 1) for i in range(len(xs) - 1)]
    for i, (north, south) in zip((1, 2, 3), ((140.0, 90.0), (110.0, 160.0), (170.0, 100.0))):
        coords[10 + i], coords[20 + i] = (xs[i], north), (xs[i], -south)
        edges += [(i, 10 + i), (i, 20 + i)]
    nodes = pd.DataFrame({"x": [c[0] for c in coords.values()], "y": [c[1] for c in coords.values()]},
                         index=pd.Index(list(coords), name="node_id"))
    template = RoadGraph(nodes.assign(lon=0.0, lat=0.0, degree=0), pd.DataFrame(columns=EDGE_COLUMNS), [], "EPSG:3067", 20.0)
    return build_graph(nodes, [{"u": u, "v": v, "oneway": 0} for u, v in edges],
                       [np.array([coords[u], coords[v]], float) for u, v in edges], template)


@pytest.fixture(scope="module")
def street_as_dual():
    """The street (the truth) and the map that draws its main street as a dual carriageway ``GAP_M`` wide."""
    street = street_graph()
    dual, _, duals = split_dual(street, [[(e, e) for e in range(4)]], np.array([GAP_M]))  # edge i runs from node i
    return street, dual, duals[0]


def test_the_dual_pairs_are_merged_along_their_middle(street_as_dual):
    _, dual, (right, left, _) = street_as_dual
    merged = merge_duals(dual, 25.0)
    assert sorted(tuple(sorted(p)) for p in merged.pairs) == sorted(tuple(sorted(p)) for p in zip(right, left))
    graph = merged.graph
    # the map's roads keep their ids, ends and geometry; four merged roads and a link from each of the pairs' ten nodes
    assert (graph.edges.iloc[:dual.num_edges][["u", "v", "oneway"]].to_numpy() == dual.edges[["u", "v", "oneway"]].to_numpy()).all()
    assert all(np.array_equal(graph.geometry[e], dual.geometry[e]) for e in range(dual.num_edges))
    added = np.flatnonzero(merged.added)
    assert len(added) == 4 + 10 and (graph.edges.oneway.iloc[added] == 0).all()
    roads = [e for e in added if graph.edges.name.iat[e] == "merged dual carriageway"]
    links = [e for e in added if e not in roads]
    # each merged road lies on the street's centreline (y = 0), from one of its nodes' x to the next
    for e in roads:
        coords = graph.geometry[e]
        assert np.abs(coords[:, 1]).max() < 1e-6
        assert {round(coords[0, 0]), round(coords[-1, 0])} in [{0, 120}, {120, 270}, {270, 360}, {360, 510}]
    assert np.allclose(graph.edges.length_m.iloc[links], GAP_M / 2.0)
    # a merged road answers as the carriageway that runs its way, a link as a carriageway at its node
    states = directed_edges(graph, "always")
    for e in roads:
        for s in (2 * e, 2 * e + 1):
            a = int(merged.origin[s])
            assert a < dual.num_edges and dual.edges.oneway.iat[a] == 1
            way = np.diff(graph.edge_coords(e, int(states.start[s]))[[0, -1], 0])[0]
            assert np.sign(way) == np.sign(np.diff(dual.geometry[a][[0, -1], 0])[0])
    for e in links:
        a = merged.origin[2 * e]
        assert a == merged.origin[2 * e + 1] and a in set(right) | set(left)
        assert graph.edges.u.iat[e] in (dual.edges.u.iat[a], dual.edges.v.iat[a])


def test_a_link_leads_from_the_middle_road_to_side_roads_only(street_as_dual):
    _, dual, (right, left, _) = street_as_dual
    merged = merge_duals(dual, 25.0)
    every = directed_edges(merged.graph, "always")
    states = merged_moves(merged, every)
    paired = set(right) | set(left)
    for s in range(states.num_states):
        a, ahead = int(states.edge[s]), {int(states.edge[t]) for t in states.next_states(s)}
        if merged.link[a]:  # on a link: on to the middle road, a side road or an opening; back only by a U-turn
            assert not ahead & paired and all(not merged.link[b] or b == a for b in ahead), (s, ahead)
        if a in paired:
            assert not any(merged.link[b] for b in ahead), (s, ahead)
        # every other move is kept
        kept = set(states.next_states(s).tolist())
        assert kept <= set(every.next_states(s).tolist())
        if not merged.link[a] and a not in paired:
            assert kept == set(every.next_states(s).tolist())
    # a side street reaches the middle road through its link, and the middle road the side street
    side = int(np.flatnonzero((dual.edges.u == 12) | (dual.edges.v == 12))[0])  # the side street north of node 2
    into = [s for s in every.states_of(np.array([side])) if any(merged.link[every.edge[t]] for t in states.next_states(s))]
    assert into, "no link from the side street"


def test_roads_that_are_no_dual_pair_are_left_alone():
    # a dual carriageway's ends, joined by U-turns of 12 m: one pair (the carriageways), the U-turns too short
    graph, _, _ = dual_carriageway(400.0, round_ends=True)
    assert [tuple(sorted(p[:2])) for p in dual_pairs(graph, 25.0)] == [(0, 3)]
    assert dual_pairs(graph, 15.0) == []  # the carriageways are 17 m apart
    # a one-way roundabout (radius 12 m, four arcs): its facing arcs run opposite ways but are not a road's sides
    angle = np.linspace(0.0, 2.0 * np.pi, 4, endpoint=False)
    nodes = pd.DataFrame({"x": 12.0 * np.cos(angle), "y": 12.0 * np.sin(angle)}, index=pd.Index(range(4), name="node_id"))
    arcs = [np.column_stack([12.0 * np.cos(t), 12.0 * np.sin(t)]) for t in
            (np.linspace(a, a + np.pi / 2.0, 8) for a in angle)]
    template = RoadGraph(nodes.assign(lon=0.0, lat=0.0, degree=0), pd.DataFrame(columns=EDGE_COLUMNS), [], "EPSG:3067", 20.0)
    roundabout = build_graph(nodes, [{"u": i, "v": (i + 1) % 4, "oneway": 1} for i in range(4)], arcs, template)
    assert dual_pairs(roundabout, 25.0) == []
    merged = merge_duals(roundabout, 25.0)
    assert merged.graph.num_edges == 4 and not merged.added.any()


def test_a_drive_along_a_road_the_map_draws_as_dual_is_placed_on_its_middle(street_as_dual):
    """The drive: down the side street north of node 1, east along the main street, down the side street south of
    node 2 and back, east along the main street to node 3, up its side street. The map has the main street as two
    carriageways 8.5 m either side of the road driven, and its side streets 8.5 m shorter: with the merged reading the
    filter's positions after it is sure are on the road driven, without it metres off."""
    street, dual, (right, left, _) = street_as_dual
    xy, yaw, _, driven = drive_along(street, [11, 1, 2, 22, 2, 3, 13])
    turn = np.radians(25.0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    odometry = Odometry((xy - xy[0]) @ rot.T, yaw + turn)
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    error = {}
    for merge in (0.0, 25.0):
        conf["localization"]["metric"]["merge_duals_m"] = merge
        road = RoadMap(dual)
        localizer = make("metric")
        observations = localizer.observe(odometry, road, conf)
        localizer.reset(road, conf)
        track = localizer.run(observations.items)
        states = np.array([p[0].state for p in track.places])
        assert states.max() < dual.num_edges  # every answer names a road of the map
        at = np.array([p[0].xy for p in track.places], float)
        truth, past = xy[observations.frame], driven[observations.frame]
        assert (track.confidence[past > 480.0] > 0.4).all()  # sure of the road from the south side street on
        on_main = (past > 600.0) & (np.abs(truth[:, 1]) < 1.0) & (truth[:, 0] > 280.0) & (truth[:, 0] < 350.0)
        up = (past > 600.0) & (truth[:, 1] > 20.0)
        assert np.isin(states[on_main], list(set(right) | set(left))).all(), (merge, states[on_main])
        error[merge] = [float(np.median(np.hypot(*(at[m] - truth[m]).T))) for m in (on_main, up)]
    assert max(error[25.0]) < 2.0 and error[0.0][0] > 7.0 and error[0.0][1] > 3.0, error


@pytest.mark.parametrize("u_turns", ["always", "dead_ends"])
def test_a_link_that_leads_nowhere_but_back_is_not_entered(u_turns):
    # the dual carriageway with U-turn stubs: at node 0 (where the south carriageway starts) the only road out is the
    # carriageway, so its link could only turn back (with u_turns always) or end (dead_ends); at node 3 it meets a stub
    graph, _, _ = dual_carriageway(400.0, round_ends=True)
    merged = merge_duals(graph, 25.0)
    states = merged_moves(merged, directed_edges(merged.graph, u_turns))
    links = np.flatnonzero(merged.link[states.edge] & states.valid)
    entered = {int(t) for s in range(states.num_states) for t in states.next_states(s)}
    to_zero = [int(s) for s in links if states.end[s] == 0]
    to_three = [int(s) for s in links if states.end[s] == 3]
    assert len(to_zero) == len(to_three) == 1
    assert to_zero[0] not in entered and to_three[0] in entered
    for s in links:  # every link entered has a way on that is not its U-turn
        if int(s) in entered:
            assert any(t != s ^ 1 for t in states.next_states(int(s))), s
