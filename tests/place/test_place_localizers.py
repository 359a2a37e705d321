"""The place localizers of the registry: online updates (one frame in, one answer out) equal the batch loops."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.localizer import PLACE_OBSERVATIONS, ROAD_OBSERVATIONS, Answer, run_batch
from topoloc.place.markov import FilterSettings, markov_localize
from topoloc.place.topometric_localization import (
    MATCH,
    NO_MATCH,
    RELOC_FAIL,
    RELOC_OK,
    LocalizeSettings,
    MatrixScorer,
    Trace,
    dead_reckoning,
    drive_frames,
    localize,
)
from topoloc.place.topometric_map import TopometricMap
from topoloc.registry import check_names, make, registry

PLACE = ("place_loop", "place_filter", "place_odometry")


@pytest.fixture(scope="module")
def drive():
    """A map of 160 vertices about 1 m apart and a repeat drive of 140 frames, 1.1 m each, with odometry 20 % long.
    Frames see their place (0.9 there, noise below 0.3 elsewhere) except a look-alike at frame 20 and frames 40-89
    (noise only: lost, relocalization fails), so that every event of the loop happens."""
    rng = np.random.default_rng(3)
    xy = np.c_[np.concatenate([[0.0], np.cumsum(rng.uniform(0.8, 1.2, 159))]), rng.normal(0.0, 0.05, 160)]
    topo = TopometricMap(np.zeros((160, 2), np.float32), np.zeros((160, 2), np.float32), xy, np.zeros(160, np.int64),
                         xy.copy(), "clear_noon")
    truth = np.searchsorted(topo.s, 1.1 * np.arange(140))
    scores = rng.uniform(0.0, 0.3, (140, 160))
    seen = np.setdiff1d(np.arange(140), np.arange(40, 90))
    scores[seen, truth[seen]] = 0.9
    scores[20, truth[20] + 8] = 0.95
    conf = {**load(None)["place"]["localize"], "sequence_frames": 2}
    return topo, np.full(140, 1.1 * 1.2), MatrixScorer(scores), conf


def online(name: str, topo: TopometricMap, conf: dict, frames: list) -> list[Answer]:
    localizer = make(name, PLACE_OBSERVATIONS)
    localizer.reset(topo, conf)
    return [localizer.update(frame) for frame in frames]


def assert_same_trace(a: Trace, b: Trace) -> None:
    assert np.array_equal(a.vertex, b.vertex) and np.array_equal(a.s, b.s) and a.event == b.event
    assert np.array_equal(a.score, b.score, equal_nan=True)


def test_registry_lists_the_place_localizers_apart_from_the_road_ones():
    place = registry(PLACE_OBSERVATIONS)
    assert set(place) == set(PLACE)
    assert all(cls.observes == "images" and not cls.requires_model and cls.label for cls in place.values())
    assert not set(PLACE) & set(registry(ROAD_OBSERVATIONS)) and set(PLACE) <= set(registry())
    assert check_names(load(None)["place"]["localize"]["localizers"], "place.localize.localizers", PLACE_OBSERVATIONS)
    with pytest.raises(InputError, match=r"^place.localize.localizers.0: unknown localizer 'metric'"):
        check_names(["metric"], "place.localize.localizers", PLACE_OBSERVATIONS)
    with pytest.raises(InputError, match=r"^--decoder.0: unknown localizer 'place_loop'"):
        check_names(["place_loop"], "--decoder", ROAD_OBSERVATIONS)


def test_loop_online_equals_the_batch_loop(drive):
    topo, ds, scorer, conf = drive
    batch = localize(topo.s, ds, scorer, LocalizeSettings.from_conf(conf))
    assert {MATCH, NO_MATCH, RELOC_OK, RELOC_FAIL} <= set(batch.event)  # every branch of the loop is exercised
    answers = online("place_loop", topo, conf, drive_frames(ds, scorer))
    assert [a.state for a in answers] == batch.vertex.tolist()
    assert [a.xy for a in answers] == [tuple(p) for p in topo.xy[batch.vertex]]
    assert [a.confidence for a in answers] == [0.0 if np.isnan(v) else min(max(v, 0.0), 1.0) for v in batch.score]
    assert_same_trace(run_batch(make("place_loop"), topo, conf, drive_frames(ds, scorer)).extra["trace"], batch)


def test_filter_online_equals_the_batch_filter(drive):
    topo, ds, scorer, conf = drive
    batch = markov_localize(topo.s, ds, scorer.scores, FilterSettings.from_conf(conf["filter"]))
    answers = online("place_filter", topo, conf, drive_frames(ds, scorer))
    assert [a.state for a in answers] == batch.vertex.tolist()
    assert [a.confidence for a in answers] == batch.score.tolist()
    assert_same_trace(run_batch(make("place_filter"), topo, conf, drive_frames(ds, scorer)).extra["trace"], batch)


def test_odometry_online_equals_dead_reckoning(drive):
    topo, ds, scorer, conf = drive
    batch = dead_reckoning(topo.s, ds)
    answers = online("place_odometry", topo, conf, drive_frames(ds, scorer))
    assert [a.state for a in answers] == batch.vertex.tolist() and {a.confidence for a in answers} == {0.0}
    assert batch.s[100] == pytest.approx(100 * 1.32) and batch.vertex[100] > 125  # 20 % too long: the truth is at 110 m
    assert_same_trace(run_batch(make("place_odometry"), topo, conf, drive_frames(ds, scorer)).extra["trace"], batch)


def test_reset_starts_over_and_keeps_the_map_structures(drive):
    topo, ds, scorer, conf = drive
    localizer = make("place_loop")
    localizer.reset(topo, conf)
    first = localizer.run(drive_frames(ds, scorer))
    search = localizer.search
    localizer.reset(topo, conf)
    assert localizer.search is search and localizer.answer() == Answer(-1, 0.0)
    assert np.array_equal(localizer.run(drive_frames(ds, scorer)).state, first.state)
    localizer.reset(topo, {**conf, "threshold": 0.99})  # another config: rebuilt, nothing accepted
    assert localizer.search is not search and MATCH not in localizer.run(drive_frames(ds, scorer)).extra["trace"].event
