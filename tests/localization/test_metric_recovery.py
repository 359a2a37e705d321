"""The metric filter where the map explains the drive badly: it finds the track again after a stretch off the
map as fast as a fresh start would, and it does not end sure on a mirror walk."""

from __future__ import annotations

import numpy as np
import pytest
from localization_helpers import drive_along, dual_carriageway, irregular_grid, loop_nodes

from topoloc.config import load
from topoloc.localization.evaluation import Judge, localized_step
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.noise import OdometryNoise, integrate_odometry
from topoloc.motion.poses import Odometry
from topoloc.odometry.map_error_drives import drive, map_truth, off_map_loop
from topoloc.odometry.map_errors import make_map_pair
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make


def conf_slices(**metric):
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    conf["localization"]["metric"].update(metric)
    return conf


def found_again(seed, **metric):
    """Metres from the return onto the map to localized again, the oracle's from there, and the share of sure wrong
    answers after it."""
    graph, _ = irregular_grid()
    road, conf = RoadMap(graph), conf_slices(**metric)
    rng = np.random.default_rng(seed)
    sim = simulate_pattern_drive(graph, 2400.0, NOISE_LEVELS["medium"], rng)
    xy, yaw, edge, back = off_map_loop(sim.gt_xy, sim.gt_yaw, sim.edge, 0.4 * sim.length_m)
    odometry = integrate_odometry(xy, yaw, OdometryNoise.from_dict(sim.noise), rng)
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    localizer = make("metric")
    observations = localizer.observe(odometry, road, conf)
    localizer.reset(road, conf)
    track = localizer.run(observations.items)
    frame = observations.frame
    on = edge[frame] >= 0
    right = np.zeros(len(frame), bool)
    right[on] = Judge(graph, 5.0).right(track.state[on], edge[frame][on], xy[frame][on])
    before, after = frame < back - 200, frame >= back
    if localized_step(right[before], driven[frame[before]], 200.0) is None or (track.confidence[~on] >= 0.9).any():
        return np.nan, np.nan, np.nan  # not on track before the loop, or sure of a road while off the map
    tail = np.arange(back, len(edge))
    oracle = Oracle(graph, road.states).count(true_path(graph, edge[tail], xy[tail], driven[tail] - driven[back]), 0, 200.0)
    step = localized_step(right[after], driven[frame[after]] - driven[back], 200.0)
    found = driven[frame[after]][step] - driven[back] if step is not None else np.inf
    return found, oracle.localized_m, float(np.mean((track.confidence[after] >= 0.9) & ~right[after]))


@pytest.mark.parametrize("seed", [4, 7])
def test_found_again_after_a_stretch_off_the_map(seed):
    found, oracle, sure_wrong = found_again(seed)
    assert np.isfinite(oracle) and found <= 1.5 * oracle + 20.0, (found, oracle)
    assert sure_wrong <= 0.01


def test_a_mirror_walk_does_not_end_sure():
    # three laps of an out-and-back on a dual carriageway with side roads at unmirrored places: the loop the other
    # way round on the other carriageway fits every turn and length (the oracle: ambiguous)
    graph, south, north = dual_carriageway(south_sides=(200.0, 300.0, 450.0), north_sides=(380.0, 520.0, 780.0))
    xy, _, edge, driven = drive_along(graph, loop_nodes(south, north, 3), start_m=30.0)
    smooth = xy.copy()
    for _ in range(6):
        smooth[1:-1] = (smooth[:-2] + smooth[1:-1] + smooth[2:]) / 3.0
    yaw = np.unwrap(np.arctan2(*np.gradient(smooth, axis=0).T[::-1]))
    road, conf = RoadMap(graph), conf_slices()
    localizer = make("metric")
    observations = localizer.observe(Odometry(smooth, yaw), road, conf)
    localizer.reset(road, conf)
    track = localizer.run(observations.items)
    assert (track.confidence < 0.9).all()
    marginal = localizer.filter.road_marginals(0)
    true_edge = int(edge[observations.frame[-1]])
    mirror = int(np.argsort(marginal)[-2] if np.argmax(marginal) == true_edge else np.argmax(marginal))
    assert marginal[true_edge] >= 0.3 and marginal[mirror] >= 0.3  # both places hold the belief
    mid = graph.edges.iloc[[true_edge, mirror]]
    assert set(mid.u.tolist() + mid.v.tolist()) & set(south.values()) and set(mid.u.tolist() + mid.v.tolist()) & set(north.values())



def out_and_back_answers(seed, **metric):
    """Right and confidence of the metric filter's answers on an out-and-back drive on the irregular grid: out, a
    U-turn where other roads meet (not a dead end), back, a U-turn, out again."""
    graph, _ = irregular_grid()
    pair = make_map_pair(graph, "lateral", "none", np.random.default_rng(seed))
    sim = drive(pair, "out_and_back", 1500.0, NOISE_LEVELS["medium"], np.random.default_rng(seed))
    edge, xy = map_truth(pair, sim.edge, sim.gt_xy, sim.gt_yaw)
    road, conf = RoadMap(pair.map), conf_slices(**metric)
    localizer = make("metric")
    observations = localizer.observe(sim.odometry, road, conf)
    localizer.reset(road, conf)
    track = localizer.run(observations.items)
    frame = observations.frame
    return Judge(pair.map, 5.0).right(track.state, edge[frame], xy[frame]), track.confidence


@pytest.mark.parametrize("seed", [1, 5])
def test_u_turns_at_junctions_keep_the_track(seed):
    # the filter turns back with the drive (U-turn chains at every node, sweeping either way): right from the
    # first third on, never sure of a wrong road
    right, confidence = out_and_back_answers(seed)
    assert right[len(right) // 3:].mean() >= 0.9
    assert ((confidence >= 0.9) & ~right).mean() <= 0.005


@pytest.mark.parametrize("seed", [1, 4])
def test_u_turns_only_at_dead_ends_lose_the_track(seed):
    # the same drives with U-turns only at dead ends, outside the model where the drive turns: lost (seed 1), or
    # sure of a wrong road where that road has a dead end that explains the turn (seed 4; with the wide ways of the
    # defaults it is lost there too, unsure)
    right, confidence = out_and_back_answers(seed, u_turns="dead_ends")
    assert right[len(right) // 3:].mean() < 0.5
    right, confidence = out_and_back_answers(seed, u_turns="dead_ends", wide_zone_m=0.0)
    assert right[len(right) // 3:].mean() < 0.5
    assert seed != 4 or ((confidence >= 0.9) & ~right).mean() > 0.05
    right, confidence = out_and_back_answers(seed)
    assert ((confidence >= 0.9) & ~right).mean() <= 0.005
