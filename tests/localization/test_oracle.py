"""The oracle on hand-made maps with a known answer."""

from __future__ import annotations

import numpy as np
from localization_helpers import make_graph

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


def drive_along(graph, nodes, step=1.0, start_offset=30.0):
    """Frames every ``step`` metres along the roads between ``nodes`` (starting ``start_offset`` into the first)."""
    xy, edge = [], []
    for a, b in zip(nodes[:-1], nodes[1:]):
        e = int(np.flatnonzero(((graph.edges.u == a) & (graph.edges.v == b)) | ((graph.edges.u == b) & (graph.edges.v == a)))[0])
        p, q = graph.nodes.loc[a, ["x", "y"]].to_numpy(float), graph.nodes.loc[b, ["x", "y"]].to_numpy(float)
        n = int(np.hypot(*(q - p)) / step)
        xy.append(p + (q - p) * np.arange(n)[:, None] / n)
        edge += [e] * n
    xy = np.vstack(xy)[int(start_offset / step):]
    edge = np.asarray(edge)[int(start_offset / step):]
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    return xy, edge, driven


def test_mirror_corridors_only_the_late_turn_tells():
    graph = mirror_corridors()
    states = directed_edges(graph)
    xy, edge, driven = drive_along(graph, [0, 1, 2, 3, 4])
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
    xy, edge, driven = drive_along(graph, [0, 1, 2, 3, 4], start_offset=60.0)
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
    xy, edge, driven = drive_along(graph, [0, 1, 2, 3, 4])
    path = true_path(graph, edge, xy, driven)
    result = Oracle(graph, states, 15.0, 0.05).count(path, len(edge) - 5, confirm_m=0.0)  # 5 m before the end
    assert result.localized_frame is None and np.isnan(result.localized_m) and result.walks[-1] > 1
