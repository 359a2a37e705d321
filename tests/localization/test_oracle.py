"""The oracle on hand-made maps with a known answer."""

from __future__ import annotations

import numpy as np
from localization_helpers import drive_along, dual_carriageway, loop_nodes, make_graph

from topoloc.localization.connectivity import directed_edges
from topoloc.localization.oracle import Oracle, true_path


def mirror_corridors():
    """Two corridors far apart, mirror images up to their last turn: 100 m, bend 30 deg left, 120 m, bend 30 deg
    left, 80 m; then corridor A turns 90 deg left into a 100 m road, corridor B 90 deg right. Nodes: A 0-5, B 10-15."""
    def corridor(origin, last_turn, first_id):
        heading, point, pts = 0.0, np.asarray(origin, float), [np.asarray(origin, float)]
        for length, turn in ((100.0, 30.0), (120.0, 30.0), (80.0, last_turn), (100.0, 0.0)):
            point = point + length * np.array([np.cos(np.radians(heading)), np.sin(np.radians(heading))])
            pts.append(point)
            heading += turn
        return {first_id + i: tuple(p) for i, p in enumerate(pts)}

    coords = corridor((0.0, 0.0), 90.0, 0) | corridor((0.0, 2000.0), -90.0, 10)
    edges = [(i, i + 1) for i in range(4)] + [(10 + i, 11 + i) for i in range(4)]
    return make_graph(coords, edges)


def test_mirror_corridors_only_the_late_turn_tells():
    graph = mirror_corridors()
    states = directed_edges(graph)
    xy, _, edge, driven = drive_along(graph, [0, 1, 2, 3, 4], start_m=30.0)
    path = true_path(graph, edge, xy, driven)
    assert (path.state == 2 * edge).all()  # driven u -> v on every road
    result = Oracle(graph, states, 15.0, 0.05).count(path, 0, confirm_m=0.0)
    crossing = driven[np.flatnonzero(np.diff(edge))[-1] + 1]  # into the last road, where A turns left and B right
    # before the last turn both corridors agree: two walks, on two places; from it on, one
    before = driven < crossing - 1.0
    assert (result.walks[before][driven[before] > 200.0] == 2).all()
    assert result.localized_frame is not None and abs(result.localized_m - crossing) <= 1.5
    assert (result.walks[driven >= crossing + 1.0] == 1).all()


def test_first_road_partly_driven_and_lengths_within_tolerance():
    graph = mirror_corridors()
    states = directed_edges(graph)
    xy, _, edge, driven = drive_along(graph, [0, 1, 2, 3, 4], start_m=60.0)
    path = true_path(graph, edge, xy, driven)
    oracle = Oracle(graph, states, 15.0, 0.05)
    result = oracle.count(path, 0, confirm_m=0.0)
    # 40 m of the first road: every road of at least 38 m, in either direction, could be it (8 roads x 2)
    assert result.walks[0] == 16 and result.places[0] == 16
    # a strict length tolerance cannot tell a 100 m road from another 100 m road: the answer is still the late turn
    assert abs(Oracle(graph, states, 15.0, 0.0).count(path, 0, 0.0).localized_m - result.localized_m) < 1e-9


def test_too_little_driven_is_never_resolved():
    graph = mirror_corridors()
    states = directed_edges(graph)
    xy, _, edge, driven = drive_along(graph, [0, 1, 2, 3, 4], start_m=30.0)
    path = true_path(graph, edge, xy, driven)
    result = Oracle(graph, states, 15.0, 0.05).count(path, len(edge) - 5, confirm_m=0.0)  # 5 m before the end
    assert result.localized_frame is None and np.isnan(result.localized_m) and result.walks[-1] > 1


#: Side roads of the oracle's dual carriageway, where the mirror image (x -> 900 - x) has none.
SIDES = {"south_sides": (300.0,), "north_sides": (520.0,)}


def test_mirror_walk_of_a_dual_carriageway_stays_ambiguous():
    # side roads where the mirror image (x -> 900 - x) has none: where roads join is no evidence for a vehicle that
    # drives straight past them, so the walk on the other carriageway, the other way round, fits as well
    graph, south, north = dual_carriageway(**SIDES)
    states = directed_edges(graph)
    xy, _, edge, driven = drive_along(graph, loop_nodes(south, north, 3), start_m=30.0)
    path = true_path(graph, edge, xy, driven)
    oracle = Oracle(graph, states, 15.0, 0.05)
    for start in range(0, len(edge) - 100, 97):
        result = oracle.count(path, start, confirm_m=100.0)
        assert result.localized_frame is None and np.isnan(result.localized_m)
        assert result.places[-1] == 2  # the true place and its mirror
        assert result.status == ("ambiguous" if result.turns >= 2 else "open")
    assert oracle.count(path, 0, 100.0).turns == 11  # three laps of four 90-degree turns, the last ends on the link


def test_a_turn_the_mirror_cannot_make_resolves_it():
    # the same loop, then a left turn into the north side road at x = 520: its mirror (x = 380 on the south
    # carriageway) has no road, so from the turn on one walk is left
    graph, south, north = dual_carriageway(**SIDES)
    states = directed_edges(graph)
    side = int(graph.edges.v.iat[-1])
    nodes = loop_nodes(south, north, 1) + [south[x] for x in sorted(south)[1:]] + [north[900.0], north[520.0], side]
    xy, _, edge, driven = drive_along(graph, nodes, start_m=30.0)
    path = true_path(graph, edge, xy, driven)
    result = Oracle(graph, states, 15.0, 0.05).count(path, 0, confirm_m=50.0)
    turn_at = driven[np.flatnonzero(edge == len(graph.edges) - 1)[0]]
    assert result.status == "resolved" and abs(result.localized_m - turn_at) <= 1.5


def test_roads_joining_on_a_straight_are_no_evidence():
    # two straight 400 m roads far apart, each then turning 90 deg left into 100 m; road A has a side road joining
    # half-way (so it is split in two), road B not: before the turn both fit, the split is no reason to choose
    coords = {0: (0.0, 0.0), 1: (200.0, 0.0), 2: (400.0, 0.0), 3: (400.0, 100.0), 4: (200.0, -100.0),
              10: (0.0, 1000.0), 11: (400.0, 1000.0), 12: (400.0, 1100.0)}
    graph = make_graph(coords, [(0, 1, 1), (1, 2, 1), (2, 3, 1), (1, 4, 1), (10, 11, 1), (11, 12, 1)])
    states = directed_edges(graph)
    xy, _, edge, driven = drive_along(graph, [0, 1, 2, 3], start_m=10.0)
    result = Oracle(graph, states, 15.0, 0.05).count(true_path(graph, edge, xy, driven), 0, confirm_m=0.0)
    before = driven < 389.0
    assert (result.places[before][driven[before] > 250.0] == 2).all()  # both straights are long enough
    assert result.status == "ambiguous" or result.turns == 1
    assert result.walks[-1] == 2 and result.localized_frame is None  # the turn is the same on both



def test_a_turn_no_road_of_the_map_makes_leaves_the_start_open():
    # the first road of corridor A, then its third (a map that lacks the road between them): a 60 deg turn that no
    # move of the map makes; no walk agrees, and the oracle says the start is open instead of failing
    graph = mirror_corridors()
    first, third = drive_along(graph, [0, 1]), drive_along(graph, [2, 3])
    xy, edge = np.concatenate([first[0], third[0]]), np.concatenate([first[2], third[2]])
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    result = Oracle(graph, directed_edges(graph), 15.0, 0.05).count(true_path(graph, edge, xy, driven), 0, 0.0)
    assert result.status == "open" and result.localized_frame is None
    assert (result.walks[driven > first[3][-1] + 1.0] == 0).all()
