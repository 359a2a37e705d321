"""The metric filter's restart (``localization.metric.restart``, on by default): a filter that has lost the track
it held races a fresh one started after the loss. Until a challenger takes over, the answers are the plain filter's;
after a stretch off a map with errors, where the plain filter is lost for good or stays lost for long, the restarted
filter finds the track again, and sooner."""

from __future__ import annotations

import numpy as np
import pytest
from localization_helpers import irregular_grid
from test_metric_recovery import conf_slices

from topoloc.localization.evaluation import Judge, localized_step
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.noise import OdometryNoise, integrate_odometry
from topoloc.odometry.map_error_drives import off_map_loop
from topoloc.odometry.map_errors import make_map_pair
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make


def loop_drive(seed: int, error: str):
    """A 2.4 km drive on the true network of the irregular grid with ``error`` at the medium level
    (:func:`~topoloc.odometry.map_errors.make_map_pair`: for ``displacement`` its nodes and curves moved, the map the
    grid itself) that leaves the road for a 120 m loop at 40 %: the map pair, the odometry, positions, true roads,
    metres driven, the return."""
    graph, _ = irregular_grid()
    rng = np.random.default_rng(seed)
    pair = make_map_pair(graph, error, "medium", rng)
    sim = simulate_pattern_drive(pair.truth, 2400.0, NOISE_LEVELS["medium"], rng)
    xy, yaw, edge, back = off_map_loop(sim.gt_xy, sim.gt_yaw, sim.edge, 0.4 * sim.length_m)
    odometry = integrate_odometry(xy, yaw, OdometryNoise.from_dict(sim.noise), rng)
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    return pair, odometry, xy, edge, driven, back


def localize(pair, odometry, **metric):
    """The metric filter's track on the pair's map, its observation frames, and the localizer."""
    road, conf = RoadMap(pair.map), conf_slices(**metric)
    localizer = make("metric")
    observations = localizer.observe(odometry, road, conf)
    localizer.reset(road, conf)
    return localizer.run(observations.items), observations.frame, localizer


def found_after(pair, track, frame, xy, edge, driven, back) -> tuple[float, float]:
    """Metres from the return onto the map until localized again (inf: never), and the share of sure wrong answers
    after the return (a neighbouring road counts near the true junction)."""
    after = frame >= back
    right = Judge(pair.map, 5.0, pair.truth.nodes).right(track.state[after], edge[frame[after]], xy[frame[after]])
    step = localized_step(right, driven[frame[after]] - driven[back], 200.0)
    found = driven[frame[after]][step] - driven[back] if step is not None else np.inf
    return found, float(np.mean((track.confidence[after] >= 0.9) & ~right))


@pytest.mark.parametrize("seed", [1, 9])
def test_a_race_without_a_takeover_keeps_the_plain_filters_answers(seed):
    # nodes and curves displaced (medium): the filter falls off the map at the loop and challengers race it (twice),
    # but none takes over; until one does, every answer and the path are the plain filter's
    pair, odometry, *_ = loop_drive(seed, "displacement")
    plain, _, _ = localize(pair, odometry, restart=False)
    restarted, _, localizer = localize(pair, odometry, restart=True)
    assert localizer.filter.restarts[0] >= 1 and localizer.filter.swaps[0] == 0
    assert np.array_equal(plain.state, restarted.state) and np.array_equal(plain.path, restarted.path)
    np.testing.assert_array_equal(plain.confidence, restarted.confidence)


@pytest.mark.parametrize("seed, sure_wrong_max", [(20, 0.01), (15, 0.1)])
def test_a_lost_track_is_found_again_sooner(seed, sure_wrong_max):
    # nodes and curves displaced (medium): after the loop the plain filter never finds the track again (seed 20:
    # lost, seed 15: sure of a wrong road in 30 % of the answers after the return); the restarted one swaps to its
    # challenger and is right again after 1397 m and 1018 m, sure and wrong in 0.1 % and 8.7 % of those answers
    pair, odometry, xy, edge, driven, back = loop_drive(seed, "displacement")
    plain, frame, _ = localize(pair, odometry, restart=False)
    plain_m, plain_sure_wrong = found_after(pair, plain, frame, xy, edge, driven, back)
    restarted, frame, localizer = localize(pair, odometry, restart=True)
    restarted_m, sure_wrong = found_after(pair, restarted, frame, xy, edge, driven, back)
    assert plain_m >= 1000.0 and np.isfinite(restarted_m) and restarted_m <= 0.6 * plain_m, (plain_m, restarted_m)
    assert sure_wrong <= sure_wrong_max and (sure_wrong < plain_sure_wrong or plain_sure_wrong == 0.0), (sure_wrong, plain_sure_wrong)
    assert localizer.filter.swaps[0] == 1 and len(restarted.path) == len(restarted.state)
    assert (restarted.path[-50:] >= 0).all()


def test_a_start_in_a_bank_is_answered_as_alone():
    # run_starts (every start of a drive in one bank, as the evaluation runs them) gives the drive's first start the
    # answers and the path of the same filter run alone, swap included; the belief and the road marginals are the
    # main filter's
    pair, odometry, *_ = loop_drive(20, "displacement")
    alone, frame, localizer = localize(pair, odometry, restart=True)
    road, conf = RoadMap(pair.map), conf_slices(restart=True)
    runs = localizer.run_starts(odometry, road, conf, np.array([0, int(frame[len(frame) // 2])]))
    _, observations, track = runs[0]
    assert np.array_equal(observations.frame, frame)
    assert np.array_equal(track.state, alone.state) and np.array_equal(track.path, alone.path)
    np.testing.assert_array_equal(track.confidence, alone.confidence)
    localizer = make("metric")
    localizer.reset(road, conf)
    localizer.start()
    for item in localizer.observe(odometry, road, conf).items:
        answer = localizer.update(item)
    marginals = localizer.filter.road_marginals(0)
    _, weight, offmap = localizer.filter.belief(0)
    assert localizer.filter.swaps[0] == 1 and marginals.argmax() == answer.state
    assert weight.sum() + offmap == pytest.approx(1.0, abs=1e-3)
