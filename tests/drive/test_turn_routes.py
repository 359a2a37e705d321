"""Training routes through the map's sharp turns (drive.demonstrations.sharp_turn_share): the turns found on a dual
carriageway are its U-turns through the median openings, a route drawn through one turns back within it, and the
share of training routes drawn so is spread over the route indices."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.conftest import make_config
from tests.drive.conftest import drive_conf, town_route
from topoloc.drive.demonstrations import sharp_turn_route, training_route, wide_middle_route
from topoloc.drive.routes import random_drive_route
from topoloc.drive.turn_routes import SHARP_TURN_DEG, TrainingRoutes, sharp_turns, turn_class
from topoloc.odometry.map_errors import dual_carriageway_grid


@pytest.fixture(scope="module")
def dual():
    """Two one-way carriageways 17 m apart, a median opening at each of their six nodes, side streets."""
    return dual_carriageway_grid().truth


def test_the_sharp_turns_of_a_dual_carriageway_are_its_u_turns_through_the_median(dual):
    turns = sharp_turns(dual)
    edges = dual.edges
    opening = set(np.flatnonzero(edges.length_m.to_numpy() < 20.0).tolist())
    # every median opening, each way it may be driven from a carriageway onto the other (the end ones one way only)
    assert len(turns) == 10 and {t.edges[1] for t in turns} == opening
    for t in turns:
        assert len(t.edges) == 3 and t.turn_deg == pytest.approx(180.0, abs=5.0)  # a left U-turn, not 0 deg
        for key, start in zip(t.edges, t.froms):  # a connected, legal way: each road driven from its start node
            u, v, oneway = int(edges.u.iat[key]), int(edges.v.iat[key]), int(edges.oneway.iat[key])
            assert start in (u, v) and not (oneway == 1 and start != u)
        assert [dual.other_end(k, n) for k, n in zip(t.edges[:-1], t.froms[:-1])] == list(t.froms[1:])
    # side streets leave at right angles: no sharp turn at a node, and none through a road longer than within_m
    assert sharp_turns(dual, within_m=10.0) == [] and sharp_turns(dual, min_turn_deg=90.0, within_m=0.0) != []


def test_turns_are_drawn_evenly_by_class_not_by_number():
    assert [turn_class(t) for t in (140.0, -150.0, 175.0, -185.0, 270.0)] == [
        (0, True), (0, False), (1, True), (1, False), (2, True)]
    graph = dual_carriageway_grid().truth
    routes = TrainingRoutes(graph, make_config(), 300.0)
    loops = [replace(t, turn_deg=270.0) for t in routes.turns[:9]]  # nine "loops" and one U-turn
    routes.__dict__["turns"] = loops + routes.turns[9:]
    firsts = [routes.through_turn(np.random.default_rng(seed)) for seed in range(40)]
    u_turn = routes.turns[9].edges[1]
    share = np.mean([r is not None and u_turn in r.edges for r in firsts])
    assert share > 0.3  # drawn evenly by class: about half, where by number it would be a tenth


def test_a_route_through_a_turn_turns_back_within_it(dual):
    conf = make_config()
    routes = TrainingRoutes(dual, conf, 300.0)
    drawn = [routes.through_turn(np.random.default_rng(seed)) for seed in range(12)]
    kept = [r for r in drawn if r is not None]
    assert len(kept) >= 6
    for route in kept:
        assert route.length_m <= 300.0 + 1.0
        heading = np.unwrap(route.yaw)
        step = int(round(45.0 / float(np.median(np.diff(route.s)))))
        assert np.abs(heading[step:] - heading[:-step]).max() >= np.radians(SHARP_TURN_DEG)  # within 45 m
        assert any(e in route.edges for e in (18, 19, 20, 21, 22, 23))  # through a median opening
    # called, it draws the plain random walk of random_drive_route
    for seed in range(5):
        plain = routes(np.random.default_rng(seed))
        same = random_drive_route(dual, conf, 300.0, np.random.default_rng(seed))
        assert (plain is None) == (same is None) and (plain is None or plain.edges == same.edges)


def test_sharp_turn_share_draws_that_share_of_the_routes_through_a_turn(town_graph, caplog):
    drive = drive_conf(demonstrations={"min_steps": 20, "min_distance_m": 0})
    conf = {"drive": drive}
    straight, right = town_route(town_graph, "straight", drive), town_route(town_graph, "right", drive)

    class Maker:  # straight on when called, the right turn through a "sharp turn"
        turns = ["a turn"]
        through = 0

        def __call__(self, rng):
            return straight

        def through_turn(self, rng):
            Maker.through += 1
            return right

    routes = 9
    for share in (0.0, 1.0 / 3.0, 1.0):
        chosen = [training_route(r, conf, None, Maker(), sharp_turn_share=share) for r in range(routes)]
        picked = [r for r in range(routes) if sharp_turn_route(r, share)]
        assert len(picked) == round(routes * share)
        assert all(chosen[r] is right for r in picked) and all(chosen[r] is straight for r in range(routes) if r not in picked)
    # a route through a turn is the first one kept: candidates rank random walks only
    Maker.through = 0
    assert training_route(1, conf, None, Maker(), candidates=4, sharp_turn_share=1.0 / 3.0) is right
    assert Maker.through == 1
    # spread half a period after wide_middle_share's routes, so that equal shares pick other routes
    assert [r for r in range(routes) if sharp_turn_route(r, 1.0 / 3.0)] == [1, 4, 7]
    assert not {1, 4, 7} & {r for r in range(routes) if wide_middle_route(r, 1.0 / 3.0)}
    Maker.turns = []
    with caplog.at_level("WARNING"):
        assert training_route(0, conf, None, Maker(), sharp_turn_share=1.0) is straight
    assert "sharp_turn_share" in caplog.text
