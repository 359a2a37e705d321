"""The metric filter's coarse phase (city scale) against the dense filter, on a small map where both run."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from localization_helpers import irregular_grid
from test_metric import NOISELESS, score

from topoloc.config import load
from topoloc.localization.metric.city_filter import CityFilter, coarse_settings, uses_coarse
from topoloc.localization.metric.dense_filter import MetricFilter
from topoloc.localization.metric.map_model import MetricModel, MetricSettings
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make


@pytest.fixture(scope="module")
def grid():
    graph, _ = irregular_grid()
    return graph, RoadMap(graph), {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}


def coarse_conf(conf: dict, handoff: int = 400) -> dict:
    """``conf`` with the coarse phase forced on this small map (it has about 3,600 cells)."""
    out = copy.deepcopy(conf)
    out["localization"]["metric"].update(coarse_min_cells=0, coarse_handoff_cells=handoff)
    return out


def run(road, conf, sim):
    localizer = make("metric")
    observations = localizer.observe(sim.odometry, road, conf)
    localizer.reset(road, conf)
    track = localizer.run(observations.items)
    return localizer, observations, track


def test_small_maps_run_the_dense_filter_unchanged(grid):
    graph, road, conf = grid
    settings = MetricSettings.from_conf(conf["localization"]["metric"])
    model = MetricModel(graph, road.states, settings)
    assert not uses_coarse(settings, model.num_cells) and uses_coarse(settings, 10**6)
    sim = simulate_pattern_drive(graph, 500.0, NOISE_LEVELS["medium"], np.random.default_rng(7))
    steps = make("metric").observe(sim.odometry, road, conf).items
    dense, city = MetricFilter(model), CityFilter(model, None)
    dense.start()
    city.start()
    for direction, yaw, _ in steps:
        dense.update(direction, yaw)
        city.update(direction, yaw)
        a, b = dense.answer(), city.answer()
        assert (a.edge, a.cell, a.confidence) == (b.edge, b.cell, b.confidence)
    assert (dense.path() == city.path()).all()


@pytest.mark.parametrize("level, seed", [("none", 1), ("medium", 2), ("high", 3)])
def test_coarse_phase_gives_the_dense_filters_answers(grid, level, seed):
    graph, road, conf = grid
    sim = simulate_pattern_drive(graph, 1500.0, NOISELESS if level == "none" else NOISE_LEVELS[level], np.random.default_rng(seed))
    _, observations, dense = run(road, conf, sim)
    localizer, _, city = run(road, coarse_conf(conf), sim)
    assert localizer.coarse_model is not None and localizer.coarse_model.settings.cell_m == 8.0
    m_dense, m_city = score(graph, sim, observations, dense), score(graph, sim, observations, city)
    # coarse cells lose some of the curves' detail while broad: the best answer right for good up to half again
    # later (high noise: at 653 m on the full grid, 875 m with the coarse phase, both unsure at 0.25-0.7 between
    # and first sure at 924 m; a quarter later before U-turns across a median and at 0.3)
    assert np.isfinite(m_city["localized_m"]) and m_city["localized_m"] <= 1.5 * m_dense["localized_m"] + 50.0, (m_dense, m_city)
    assert m_city["accuracy_after"] >= 0.97 and m_city["confident_wrong"] <= 0.02, m_city
    # once both are sure: the same roads, and positions within a cell (high noise, seed 3: the belief handed over from
    # 8 m cells is a cell behind the dense one's at the median, 2.6 m from the truth against 1.8 m)
    later = np.arange(len(dense.state)) >= 0.6 * len(dense.state)
    assert np.mean(dense.state[later] == city.state[later]) >= 0.99
    assert np.nanmedian(np.hypot(*(dense.xy[later] - city.xy[later]).T)) <= conf["localization"]["metric"]["cell_m"]


@pytest.mark.parametrize("extra", [{"wide_zone_m": 0.0, "u_turn_gap_m": 0.0}, {"wide_zone_m": 0.0},
                                   {"wide_zone_m": 20.0, "wide_share": 0.1},
                                   {"turn_path": "arc", "wide_zone_m": 20.0, "wide_share": 0.5}])
def test_every_fine_cell_lies_in_the_coarse_cell_at_its_place(grid, extra):
    """The coarse chains have neither U-turns across a median nor wide ways: each fine cell of those must still fall
    in a coarse cell at its place on the map (a tight turn's, or its road's middle), within one coarse cell (without
    either, the fine chains are the coarse ones)."""
    graph, road, conf = grid
    settings = MetricSettings.from_conf({**coarse_conf(conf)["localization"]["metric"], **extra})
    fine = MetricModel(graph, road.states, settings)
    coarse = MetricModel(graph, road.states, coarse_settings(settings))
    bank = CityFilter(fine, coarse)
    assert coarse.grid.chains.plain_turn is None  # the plain chains
    fg, cg = fine.grid, coarse.grid
    assert (np.bincount(bank.coarse_of, minlength=coarse.num_cells) > 0).all()  # every coarse cell covers fine cells
    np.testing.assert_allclose(np.bincount(bank.coarse_of, weights=bank.share, minlength=coarse.num_cells), 1.0)
    apart = np.hypot(*(fg.xy - cg.xy[bank.coarse_of]).T)
    assert apart.max() <= 0.5 * cg.cell_len.max() + 1.0, apart.max()  # a coarse cell of 8 m stands for its centre
    assert (fg.state[bank.coarse_of >= 0] == cg.state[bank.coarse_of]).mean() >= 0.97  # off only at the node
    if settings.wide_zone_m > 0:  # an approach takes its vehicles' share of the coarse cells it shares with wide turns
        approach = (fg.chains.second_state[fg.chain] < 0) & (fg.chains.weight[fg.chain] != 1.0)
        cells = np.unique(bank.coarse_of[approach])
        part = np.bincount(bank.coarse_of[approach], weights=bank.share[approach], minlength=coarse.num_cells)[cells]
        expected = 1.0 - settings.wide_share  # by length alone a third to a half (0.82-0.90 and 0.40-0.58 when written)
        assert np.median(part) == pytest.approx(expected, abs=0.05) and part.min() >= expected - 0.15, part


def test_coarse_phase_hands_over_and_back(grid):
    graph, road, conf = grid
    settings = MetricSettings.from_conf(coarse_conf(conf)["localization"]["metric"])
    fine = MetricModel(graph, road.states, settings)
    coarse = MetricModel(graph, road.states, coarse_settings(settings))
    bank = CityFilter(fine, coarse, filters=2)
    assert coarse.num_cells * 3 < fine.num_cells
    assert (np.bincount(bank.coarse_of, minlength=coarse.num_cells) > 0).all()  # every coarse cell covers fine cells
    assert np.allclose(np.bincount(bank.coarse_of, weights=bank.share), 1.0)
    sim = simulate_pattern_drive(graph, 1200.0, NOISE_LEVELS["medium"], np.random.default_rng(4))
    steps = make("metric").observe(sim.odometry, road, conf).items
    bank.start([0, 1])
    phases = []
    for direction, yaw, _ in steps:
        bank.update(direction, yaw)
        phases.append(bank.in_coarse.copy())
        xy, weight, offmap = bank.belief(0)
        assert abs(weight.sum() + offmap - 1.0) < 1e-4
    phases = np.array(phases)
    assert phases[0].all() and not phases[-1].any()  # coarse at first, fine once the belief narrowed
    assert len(bank.path(0)) == len(steps) and (bank.path(0)[-50:] >= 0).all()

    # then the drive leaves the map (turns of 40 degrees every 15 m, which no road makes): the fine filter gets
    # lost and goes back to coarse cells
    yaw = sim.odometry.yaw[-1] + np.radians(40.0) * np.where((np.arange(400) // 15) % 2 == 0, 1.0, -1.0)
    xy = sim.odometry.xy[-1] + np.cumsum(np.column_stack([np.cos(yaw), np.sin(yaw)]), axis=0)
    odometry = Odometry(np.vstack([sim.odometry.xy, xy]), np.concatenate([sim.odometry.yaw, yaw]))
    lost = CityFilter(fine, coarse)
    lost.start()
    phases, sure = [], []
    for direction, yaw, _ in make("metric").observe(odometry, road, conf).items:
        lost.update(direction, yaw)
        phases.append(lost.in_coarse[0])
        sure.append(lost.answer().confidence >= 0.9)
    phases, sure = np.array(phases), np.array(sure)
    assert not phases[len(steps) - 1] and phases[-1]  # fine at the end of the drive on the map, coarse again off it
    assert not sure[-50:].any()


@pytest.mark.parametrize("cells, share", [(400, 1.0), (100000, 0.125), (100000, 0.5), (300, 0.125)])
def test_handoff_is_the_fewer_of_its_cells_and_its_share_of_the_map(grid, cells, share):
    graph, road, conf = grid
    metric = coarse_conf(conf, cells)["localization"]["metric"]
    settings = MetricSettings.from_conf({**metric, "coarse_handoff_share": share})
    fine = MetricModel(graph, road.states, settings)
    bank = CityFilter(fine, MetricModel(graph, road.states, coarse_settings(settings)))
    assert bank.handoff == int(min(cells, share * fine.num_cells)) // settings.coarse_factor  # in coarse entries
    assert MetricSettings.from_conf(load(None)["localization"]["metric"]).coarse_handoff_share == 1.0  # off: the cells alone


def test_a_smaller_share_of_the_map_keeps_a_start_coarse_for_longer(grid):
    graph, road, conf = grid
    sim = simulate_pattern_drive(graph, 800.0, NOISE_LEVELS["medium"], np.random.default_rng(4))
    steps = make("metric").observe(sim.odometry, road, conf).items
    handed_at = {}
    for share in (1.0, 0.06):
        settings = MetricSettings.from_conf({**coarse_conf(conf)["localization"]["metric"], "coarse_handoff_share": share})
        fine = MetricModel(graph, road.states, settings)
        bank = CityFilter(fine, MetricModel(graph, road.states, coarse_settings(settings)))
        bank.start()
        for j, (direction, yaw, _) in enumerate(steps):
            bank.update(direction, yaw)
            if not bank.in_coarse[0]:
                handed_at[share] = j
                break
    assert handed_at[1.0] < handed_at.get(0.06, len(steps)), handed_at  # 400 cells, then 6 % of the map: about 220


def test_evidence_counts_a_coarse_step_for_the_fine_steps_it_stands_for(grid):
    """The restart's race weighs a challenger that began on coarse cells against a filter on the full grid: their
    log-likelihoods must count the same drive alike (with one term per coarse step it was 59 % of the dense filter's)."""
    graph, road, conf = grid
    sim = simulate_pattern_drive(graph, 800.0, NOISE_LEVELS["medium"], np.random.default_rng(4))
    steps = make("metric").observe(sim.odometry, road, conf).items
    settings = MetricSettings.from_conf(coarse_conf(conf)["localization"]["metric"])
    fine = MetricModel(graph, road.states, settings)
    city, dense = CityFilter(fine, MetricModel(graph, road.states, coarse_settings(settings))), MetricFilter(fine)
    city.start()
    dense.start()
    coarse_steps = 0
    for direction, yaw, _ in steps:
        coarse_steps += int(city.in_coarse[0])
        city.update(direction, yaw)
        dense.update(direction, yaw)
    assert 100 <= coarse_steps <= len(steps) - 100, coarse_steps  # a good part of the drive in each phase
    # a coarse belief predicts a yaw less sharply than the full grid's, so it stays a little below (87 % when written)
    assert 0.8 * dense.evidence[0] <= city.evidence()[0] <= 1.05 * dense.evidence[0], (city.evidence()[0], dense.evidence[0])


def test_handed_over_belief_is_the_coarse_one_at_that_step(grid):
    """A coarse belief handed over stands for the position after the step that handed it over: the fine filter
    must not take that step a second time (which would move the mass one fine cell ahead of the coarse one)."""
    graph, road, conf = grid
    settings = MetricSettings.from_conf(coarse_conf(conf)["localization"]["metric"])
    fine = MetricModel(graph, road.states, settings)
    bank = CityFilter(fine, MetricModel(graph, road.states, coarse_settings(settings)), filters=3)
    handed: dict[int, tuple] = {}
    to_fine = bank._to_fine

    def record(b: int) -> None:
        mine = bank.coarse.group // bank.coarse.classes == b
        handed[b] = np.bincount(bank.coarse.cell[mine], weights=bank.coarse.weight[mine], minlength=bank.coarse.num_cells)
        to_fine(b)

    bank._to_fine = record
    sim = simulate_pattern_drive(graph, 1000.0, NOISE_LEVELS["low"], np.random.default_rng(5))
    steps = make("metric").observe(sim.odometry, road, conf).items
    checked = 0
    for j, (direction, yaw, _) in enumerate(steps):
        if j in (0, 5, 11):  # starts at several phases of the coarse steps
            bank.start([0, 5, 11].index(j))
        handed.clear()
        bank.update(direction, yaw)
        for b, coarse_weight in handed.items():
            mine = bank.fine.group // bank.fine.classes == b
            image = np.bincount(bank.coarse_of[bank.fine.cell[mine]], weights=bank.fine.weight[mine],
                                minlength=bank.coarse.num_cells)
            assert np.abs(image / image.sum() - coarse_weight / coarse_weight.sum()).sum() < 1e-3
            checked += 1
    assert checked == 3


def test_coarse_answers_kept_between_coarse_steps_are_the_current_ones(grid):
    """The coarse answers are computed once per coarse step and reused: through resets of some filters, handoffs
    and later steps they equal answers computed afresh at every step."""
    graph, road, conf = grid
    settings = MetricSettings.from_conf(coarse_conf(conf)["localization"]["metric"])
    fine = MetricModel(graph, road.states, settings)
    coarse = MetricModel(graph, road.states, coarse_settings(settings))
    kept, fresh = CityFilter(fine, coarse, filters=3), CityFilter(fine, coarse, filters=3)
    sim = simulate_pattern_drive(graph, 800.0, NOISE_LEVELS["medium"], np.random.default_rng(6))
    steps = make("metric").observe(sim.odometry, road, conf).items
    phases = []
    for j, (direction, yaw, _) in enumerate(steps):
        if j in (0, 3, 9):
            kept.start([0, 3, 9].index(j))
            fresh.start([0, 3, 9].index(j))
        kept.update(direction, yaw)
        fresh.update(direction, yaw)
        fresh._coarse_answers = None  # what an uncached filter would answer
        for a, b in zip(kept.answers(), fresh.answers()):
            assert (a.edge, a.cell, a.confidence) == (b.edge, b.cell, b.confidence)
        phases.append(kept.in_coarse.copy())
    phases = np.array(phases)
    assert phases[:, 0].any() and not phases[-1].all()  # the comparison covered both phases
