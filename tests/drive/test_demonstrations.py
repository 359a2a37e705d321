"""Demonstrations: side views teach the recovery (labels steer back towards the lane) without changing the drive,
and routes can share out the training conditions."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.conftest import make_config
from tests.drive.conftest import drive_conf, road_simulator, tiny_demos, town_route
from topoloc.drive.controller_training import DemoData
from topoloc.drive.demonstrations import (
    LOCAL_PATH_M,
    WIDE_MIDDLE_MIN,
    Demonstrations,
    SideViews,
    collect_demonstrations,
    demonstrate,
    demonstrate_route,
    local_path,
    record,
    route_conditions,
    sharp_m,
    training_route,
    wide_middle_route,
)
from topoloc.drive.expert import Expert, ExpertSettings, NoiseSettings
from topoloc.drive.routes import make_simulator, random_drive_route
from topoloc.drive.simulator import SUCCESS


@pytest.fixture(scope="module")
def short_road(straight_road):
    drive = drive_conf()
    return drive, road_simulator(straight_road, drive, 80.0)


def test_side_views_label_the_way_back_and_leave_the_drive_alone(short_road):
    drive, sim = short_road
    expert = Expert(sim.route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    noise = NoiseSettings.from_conf(drive["noise"])
    plain, status = record(sim, expert, "clear_noon", 3, noise, 2, True, ["clear_noon"], 0)
    assert status == SUCCESS
    side, status = record(sim, expert, "clear_noon", 3, noise, 2, True, ["clear_noon"], 0, SideViews(1, 1.5, 10.0))
    assert status == SUCCESS and len(side) == 2 * len(plain)
    own, extra = np.arange(0, len(side), 2), np.arange(1, len(side), 2)
    np.testing.assert_array_equal(side.images[own], plain.images)  # the drive itself is the same
    np.testing.assert_allclose(side.steer[own], plain.steer)
    assert side.perturbed[extra].all()
    lateral, steer = side.lateral[extra], side.steer[extra]
    assert np.abs(lateral).max() > 1.0 and np.abs(lateral).max() <= 1.6
    far = np.abs(lateral) > 0.7  # + right of the lane: steer left (+), and the other way round
    assert far.sum() > 5 and np.all(np.sign(steer[far]) == np.sign(lateral[far]))
    assert not np.array_equal(side.images[extra], side.images[own])


def test_routes_share_out_the_conditions():
    assert route_conditions(0, 5, None) == [0, 1, 2, 3, 4]
    assert route_conditions(3, 5, 1) == [3]
    assert route_conditions(4, 5, 2) == [4, 0]
    assert route_conditions(1, 2, 5) == [0, 1]
    assert sorted(c for r in range(5) for c in route_conditions(r, 5, 1)) == [0, 1, 2, 3, 4]


def test_steer_balance_draws_sharp_bends_as_often_as_straight_on():
    n = 400
    steer = np.where(np.arange(n) % 20 == 0, 0.6, 0.02).astype(np.float32)  # one step in 20 in a sharp bend
    demos = Demonstrations(np.zeros((n, 4, 4, 3), np.uint8), ["clear_noon"], np.repeat([0, 1], n // 2), np.zeros(n, np.int64),
                           np.full(n, 5.0, np.float32), np.zeros(n, np.int64), steer, np.zeros(n, np.float32),
                           np.full(n, 5.0, np.float32), np.zeros(n, bool), np.zeros((n, 2)), np.zeros(n), np.zeros(n, np.float32),
                           np.zeros((n, LOCAL_PATH_M, 2), np.float32))
    train = {"batch_size": 8, "batches_per_epoch": 1, "seed": 0}
    share = lambda data: data.weights[steer[data.train_idx] > 0.5].sum() / data.weights.sum()
    assert np.isclose(share(DemoData(demos, 1, train, 12.0)), 0.05)
    assert np.isclose(share(DemoData(demos, 1, train | {"steer_balance": True}, 12.0)), 0.5)
    # Topo-LP's path noise: drawn anew for every training draw, once per validation step (epochs compare)
    demos.path[:] = np.column_stack([np.arange(1.0, LOCAL_PATH_M + 1), np.zeros(LOCAL_PATH_M)])[None].astype(np.float32)
    data = DemoData(demos, 1, train, 12.0, {"shift_m": 2.0, "yaw_deg": 3.0})
    val, fit = data._steps(data.val_idx, 1), data._steps(data.train_idx, 0)
    assert all(np.array_equal(val[i][2], val[i][2]) for i in range(5))
    assert not all(np.array_equal(fit[i][2], fit[i][2]) for i in range(5))


def test_the_stats_tell_noise_injection_from_side_views(short_road):
    _, sim = short_road
    conf = {"drive": drive_conf(noise={"share": 0.3}, demonstrations={"routes": 2, "val_routes": 1, "min_steps": 20,
                                                                      "conditions": ["clear_noon"], "side_views": 1}),
            "place": make_config()["place"]}
    demos, facts = demonstrate(None, None, conf, None, lambda rng: sim.route, lambda route: sim)
    assert facts["expert_success_rate"] == 1.0 and facts["steps"] == len(demos)
    assert 0.1 < facts["noise_injected_share"] < 0.6  # of the drive's own steps, as drive.noise.share asks
    # every side view is off the expert's path: half of the steps, plus the drive's perturbed ones
    assert facts["perturbed_share"] == pytest.approx(0.5 * (1.0 + facts["noise_injected_share"]))


def test_the_local_path_goes_on_straight_past_the_routes_end(short_road):
    _, sim = short_road
    route = sim.route
    s = route.length_m - 5.0
    path = local_path(route, s, route.point(s), float(route.yaw[route.index(s)]))
    np.testing.assert_allclose(path[:, 0], np.arange(1.0, LOCAL_PATH_M + 1), atol=0.05)  # not piled up at the end
    np.testing.assert_allclose(path[:, 1], 0.0, atol=0.05)


def test_candidates_keep_the_training_route_with_the_most_sharp_bends(town_graph):
    """drive.demonstrations.candidates: of that many routes drawn (each keeping min_steps), the one with the most lane
    in bends of under 15 m radius; one candidate is the first route drawn."""
    drive = drive_conf(demonstrations={"min_steps": 20, "min_distance_m": 0})
    conf = {"drive": drive}
    straight, right = town_route(town_graph, "straight", drive), town_route(town_graph, "right", drive)
    assert sharp_m(straight) == 0.0 and sharp_m(right) > 5.0
    drawn = []

    def make_route(rng):  # straight, the right turn, straight, ... (a dead end every third draw)
        drawn.append(len(drawn))
        return [straight, None, right][(len(drawn) - 1) % 3]

    assert training_route(0, conf, None, make_route) is straight and len(drawn) == 1
    drawn.clear()
    assert training_route(0, conf, None, make_route, candidates=2) is right and len(drawn) == 3
    drawn.clear()
    assert training_route(0, conf, None, make_route, candidates=3) is right and len(drawn) == 4


def test_routes_recorded_in_another_order_are_the_same_demonstrations(town, town_graph):
    """A route's drives depend on its index and the config alone (demonstrate_route): recorded last to first, each
    in a fresh simulator, they are the same steps, images and facts as demonstrate's (so routes can be recorded in
    separate processes)."""
    conf = make_config(place={"image": {"width": 64, "height": 48}},
                       drive={"demonstrations": {"routes": 3, "val_routes": 1, "route_length_m": 120, "min_steps": 20,
                                                 "min_distance_m": 0, "side_views": 1, "conditions": ["clear_noon", "rain"],
                                                 "conditions_per_route": 1}})
    makers = (lambda rng: random_drive_route(town_graph, conf, 120.0, rng),
              lambda route: make_simulator(str(town["osm"]), town_graph, route, conf))
    alone, facts = demonstrate(str(town["osm"]), town_graph, conf, None, *makers)
    backwards = {r: demonstrate_route(r, conf, None, *makers) for r in (2, 1, 0)}
    parts, outcomes, injected = ([p for r in range(3) for p in backwards[r][i]] for i in range(3))
    again, facts_again = collect_demonstrations(parts, outcomes, injected, conf, None)
    assert facts == facts_again and facts["routes"] == 3 and len(np.unique(alone.route)) == 3
    assert np.array_equal(alone.images, again.images) and alone.conditions == again.conditions
    for name in Demonstrations.FIELDS:
        assert np.array_equal(getattr(alone, name), getattr(again, name)), name


def test_wide_middle_share_draws_routes_in_the_middle_of_wide_unmarked_roads(town_graph, caplog):
    """drive.demonstrations.wide_middle_share: that share of the routes, spread over the indices, is drawn with at
    least half its lane in the middle of a wide road without a centre line; the lane length of the drawn routes on such
    roads is at least share * WIDE_MIDDLE_MIN; 0 keeps the plain draws; a map without such roads falls back to them."""
    drive = drive_conf(demonstrations={"min_steps": 20, "min_distance_m": 0})
    conf = {"drive": drive}
    narrow = town_route(town_graph, "straight", drive)
    n = len(narrow.s)
    wide = replace(narrow, width=np.full(n, 8.0), marked=np.zeros(n, bool))
    marked = replace(narrow, width=np.full(n, 8.0), marked=np.ones(n, bool))  # wide but two-way: keep right
    assert narrow.wide_middle_share == 0.0 and marked.wide_middle_share == 0.0 and wide.wide_middle_share == 1.0
    drawn: list[int] = []

    def make_route(rng):  # narrow, marked, dead end, wide, ...
        drawn.append(len(drawn))
        return [narrow, marked, None, wide][(len(drawn) - 1) % 4]

    routes = 9
    for share in (0.0, 1.0 / 3.0, 0.5, 1.0):
        chosen = []
        for r in range(routes):
            drawn.clear()
            chosen.append(training_route(r, conf, None, make_route, wide_middle_share=share))
        picked = [r for r in range(routes) if wide_middle_route(r, share)]
        assert len(picked) == int(np.floor(routes * share))
        assert all(chosen[r] is wide for r in picked) and all(chosen[r] is narrow for r in range(routes) if r not in picked)
        lane = np.array([c.length_m for c in chosen])
        assert (lane * [c.wide_middle_share for c in chosen]).sum() / lane.sum() >= share * WIDE_MIDDLE_MIN - 1e-9
    assert [r for r in range(routes) if wide_middle_route(r, 1.0 / 3.0)] == [2, 5, 8]  # spread, not the first ones
    with caplog.at_level("WARNING"):
        assert training_route(0, conf, None, lambda rng: narrow, wide_middle_share=1.0) is narrow
    assert "wide_middle_share" in caplog.text


def test_pooled_maps_keep_their_steps_and_each_map_gives_validation_routes():
    """Demonstrations.pool: every map's steps, in order, under route ids of their own (route k of map i: k * n + i),
    so the last val_routes routes, DemoData's validation routes, come from every map."""
    maps = [tiny_demos([0, 1, 2, 3], tag=0.0), tiny_demos([0, 1, 2, 3], tag=100.0), tiny_demos([0, 1, 2, 3], tag=200.0)]
    pooled = Demonstrations.pool(maps)
    assert len(pooled) == sum(len(m) for m in maps) and pooled.conditions == ["clear_noon", "rain"]
    at = np.cumsum([0, *(len(m) for m in maps)])
    for i, m in enumerate(maps):
        part = slice(at[i], at[i + 1])
        np.testing.assert_array_equal(pooled.images[part], m.images)
        np.testing.assert_array_equal(pooled.speed[part], m.speed)
        np.testing.assert_array_equal(pooled.condition[part], m.condition)
        np.testing.assert_array_equal(pooled.route[part], m.route * 3 + i)
    # a route's steps stay one route, and no two maps' routes share an id
    ids = {(i, r): set(pooled.route[at[i]:at[i + 1]][m.route == r]) for i, m in enumerate(maps) for r in range(4)}
    assert all(len(v) == 1 for v in ids.values()) and len(set.union(*ids.values())) == 12
    last = np.unique(pooled.route)[-3:]
    assert sorted(int(r) % 3 for r in last) == [0, 1, 2]  # one validation route of each map
    data = DemoData(pooled, 3, {"batch_size": 4, "batches_per_epoch": 1, "seed": 0}, 12.0)
    assert {int(s) // 100 for s in pooled.speed[data.val_idx]} == {0, 1, 2}  # the steps of every map validate


def test_maps_with_other_images_or_conditions_do_not_pool():
    base = tiny_demos([0, 1])
    with pytest.raises(ValueError, match="images"):
        Demonstrations.pool([base, tiny_demos([0, 1], shape=(4, 6, 1))])
    with pytest.raises(ValueError, match="images"):
        Demonstrations.pool([base, tiny_demos([0, 1], shape=(5, 6, 3))])
    with pytest.raises(ValueError, match="conditions"):
        Demonstrations.pool([base, tiny_demos([0, 1], conditions=("rain", "clear_noon"))])  # the indices would mean others
    with pytest.raises(ValueError, match="conditions"):
        Demonstrations.pool([base, base, tiny_demos([0, 1], conditions=("clear_noon",))])


def test_maps_with_fewer_routes_still_give_validation_routes():
    """Maps of other route counts (drive.demonstrations.routes set per region) pool with their last routes side by
    side: the last routes of the pooled set are still every map's last ones."""
    pooled = Demonstrations.pool([tiny_demos(list(range(10)), tag=0.0), tiny_demos([0, 1, 2], tag=100.0)])
    assert len(np.unique(pooled.route)) == 13
    last = np.unique(pooled.route)[-2:]
    assert {int(s) // 100 for s in pooled.speed[np.isin(pooled.route, last)]} == {0, 1}
    assert {int(s) % 100 // 3 for s in pooled.speed[np.isin(pooled.route, last)]} == {9, 2}  # each map's last route
