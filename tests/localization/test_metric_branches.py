"""The metric filter's options ``branches`` (how probability goes on at a node) and ``node_offset_deg`` (the heading
offset's extra spread through a node), on hand-made maps with a known answer."""

from __future__ import annotations

import numpy as np
import pytest
from localization_helpers import drive_along, make_graph

from topoloc.config import load
from topoloc.localization.connectivity import directed_edges
from topoloc.localization.metric.map_model import MetricModel, MetricSettings
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.registry import make


def conf_slices(**metric):
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    conf["localization"]["metric"].update(metric)
    return conf


def twin_roads():
    """Two straight one-way roads of 400 m, far apart, each with a node half-way: road A (0 -> 1 -> 2, edges 0, 1)
    has a one-way side road leaving it there to the south (1 -> 3, edge 2), road B (10 -> 11 -> 12, edges 3, 4)
    has none."""
    coords = {0: (0.0, 0.0), 1: (200.0, 0.0), 2: (400.0, 0.0), 3: (200.0, -150.0),
              10: (0.0, 1000.0), 11: (200.0, 1000.0), 12: (400.0, 1000.0)}
    return make_graph(coords, [(0, 1, 1), (1, 2, 1), (1, 3, 1), (10, 11, 1), (11, 12, 1)])


def model_of(graph, **metric) -> MetricModel:
    return MetricModel(graph, directed_edges(graph), MetricSettings.from_conf(conf_slices(**metric)["localization"]["metric"]))


def test_walks_keeps_each_way_on_whole_equal_splits_it():
    graph = twin_roads()
    grid = model_of(graph, wide_zone_m=0.0).grid  # ways of equal weight (a wide way weighs a ninth of the way on)
    for distance in (grid.cell_m, 2.0 * grid.cell_m):
        moves_equal, moves_walks = grid.moves(distance, split=True), grid.moves(distance, split=False)
        out_equal = np.bincount(moves_equal.src, weights=moves_equal.weight, minlength=grid.num_cells)
        out_walks = np.bincount(moves_walks.src, weights=moves_walks.weight, minlength=grid.num_cells)
        # equal: a move never makes probability (it only loses some off a dead end); walks: a move across the fork
        # hands the whole probability to each of the two roads on, elsewhere it is the same move
        assert out_equal.max() <= 1.0 + 1e-9
        forks = out_walks > 1.0 + 1e-9
        assert forks.any() and np.allclose(out_walks[forks], 2.0) and np.allclose(out_equal[forks], 1.0)
        assert np.allclose(out_walks[~forks], out_equal[~forks])
    # the model's steps follow the option
    equal, walks = model_of(graph, branches="equal"), model_of(graph, branches="walks")
    assert np.asarray(equal.forward.sum(axis=1)).max() <= 1.0 + 1e-5 < np.asarray(walks.forward.sum(axis=1)).max()


def road_shares(branches: str) -> tuple[float, float]:
    """The probability of road A (edges 0, 1) and road B (edges 3, 4) at the end of a straight drive of 360 m east on
    A, past its side road (the odometry in a frame of its own)."""
    graph = twin_roads()
    xy, yaw, _, _ = drive_along(graph, [0, 1, 2], start_m=20.0)
    xy, yaw = xy[xy[:, 0] <= 380.0], yaw[xy[:, 0] <= 380.0]
    road, conf = RoadMap(graph), conf_slices(branches=branches)
    localizer = make("metric")
    observations = localizer.observe(Odometry(xy - xy[0], yaw), road, conf)
    localizer.reset(road, conf)
    places = localizer.run(observations.items).places[-1]  # a place's state is its road (edge id)
    share = {e: sum(p.probability for p in places if p.state == e) for e in range(5)}
    return share[0] + share[1], share[3] + share[4]


def test_a_road_past_a_side_road_loses_half_with_equal_nothing_with_walks():
    a_equal, b_equal = road_shares("equal")
    a_walks, b_walks = road_shares("walks")
    assert a_equal + b_equal > 0.9 and a_walks + b_walks > 0.9  # nothing else explains the drive (each renormalized)
    assert a_equal / b_equal == pytest.approx(0.5, abs=0.1)  # the side road took half of A's probability
    assert a_walks / b_walks == pytest.approx(1.0, abs=0.1)  # every walk a priori as likely


def test_node_offset_widens_the_offset_spread_on_turns_only():
    graph = twin_roads()
    base, wide = model_of(graph, node_offset_deg=0.0), model_of(graph, node_offset_deg=10.0)
    on_turn = base.grid.chains.second_state[base.grid.chain] >= 0
    assert on_turn.any() and (~on_turn).any()
    plain = float(np.radians(base.settings.offset_drift_deg) ** 2 * base.settings.cell_m / 100.0)
    assert np.allclose(base.drift, plain)  # 0: the offset only drifts, as without the option
    assert np.allclose(wide.drift[~on_turn], plain) and (wide.drift[on_turn] > plain).all()
    # the extra variance is spread over each turn chain: its cells add up to node_offset_deg squared
    chain = base.grid.chain[on_turn]
    extra = np.bincount(chain, weights=(wide.drift - base.drift)[on_turn].astype(float))[np.unique(chain)]
    assert np.allclose(extra, np.radians(10.0) ** 2, rtol=1e-4)


def test_u_turns_at_every_node_take_their_weight_and_a_dead_end_keeps_the_whole():
    # two-way roads: 0 -> 1 -> 2 (a dead end) with a side road 1 -> 3; U-turns at every node at weight 0.02
    graph = make_graph({0: (0.0, 0.0), 1: (200.0, 0.0), 2: (400.0, 0.0), 3: (200.0, -150.0)},
                       [(0, 1, 0), (1, 2, 0), (1, 3, 0)])
    settings = MetricSettings.from_conf(conf_slices(u_turns="always", u_turn_weight=0.02)["localization"]["metric"])
    grid = MetricModel(graph, directed_edges(graph, "always"), settings).grid
    chains = grid.chains
    u_turn = (chains.second_state >= 0) & (chains.second_state == (chains.first_state ^ 1))
    assert u_turn.any() and set(np.sign(chains.turn[u_turn])) == {-1.0, 1.0}  # each U-turn sweeps both ways
    for split in (True, False):
        moves = grid.moves(3.0 * grid.cell_m, split)
        out = np.bincount(moves.src, weights=moves.weight, minlength=grid.num_cells)
        into_u = np.bincount(moves.src, weights=moves.weight * u_turn[grid.chain[moves.dst]], minlength=grid.num_cells)
        at_junction = (into_u > 0) & (out > into_u + 1e-9)  # cells whose moves reach a U-turn and another way
        at_dead_end = (into_u > 0) & ~at_junction
        assert at_junction.any() and at_dead_end.any()
        if split:  # shares: the U-turn 0.02 of another way's (two ways on at node 1: 0.02 / 2.02 of the whole)
            assert np.allclose(out, 1.0) and np.allclose(into_u[at_junction] / out[at_junction], 0.02 / 2.02, rtol=0.05)
        else:  # walks: every way on keeps the whole, the U-turn 0.02 of it; a dead end's U-turn the whole
            assert np.allclose(into_u[at_junction], 0.02, rtol=0.05) and np.allclose(into_u[at_dead_end], 1.0)
