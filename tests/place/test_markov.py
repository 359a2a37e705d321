"""The Bayes filter on synthetic score matrices: it follows the motion, ignores a false peak, finds a lost vehicle."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.place.markov import FilterSettings, markov_localize, predict

M = 200
VERTEX_S = np.arange(M, dtype=float)  # vertices 1 m apart
DEFAULTS = load(None)["place"]["localize"]["filter"]


def settings(**changes) -> FilterSettings:
    """The filter's settings of the default config, with ``changes``."""
    return FilterSettings.from_conf({**DEFAULTS, **changes})


def scores_at(truth: np.ndarray, peak: float = 0.9, other: float = 0.1) -> np.ndarray:
    """Frame t scores ``peak`` at vertex ``truth[t]`` and ``other`` everywhere else."""
    scores = np.full((len(truth), M), other)
    scores[np.arange(len(truth)), truth] = peak
    return scores


def test_prediction_moves_the_belief_by_the_odometry_and_keeps_it_normalised():
    belief = np.zeros(M)
    belief[50] = 1.0
    moved = predict(belief, VERTEX_S, 10.0, settings(motion_sigma_m=0.5, motion_sigma_rel=0.0, mixing=0.0), 1.0)
    assert int(np.argmax(moved)) == 60 and moved.sum() == pytest.approx(1.0)
    assert moved[58:63].sum() > 0.99  # a Gaussian of 0.5 m


def test_follows_the_drive_and_ignores_a_single_false_peak():
    truth = np.arange(60)
    scores = scores_at(truth)
    scores[30] = 0.1
    scores[30, 45] = 1.0  # frame 30 looks most like a place 15 m ahead
    trace = markov_localize(VERTEX_S, np.ones(60), scores, settings())
    assert list(trace.vertex) == list(truth)
    assert set(trace.event) == {"filter"}
    assert trace.score.min() > 0.5 and trace.score[30] < trace.score[29] - 0.1  # sure throughout; the false peak costs


def test_finds_a_vehicle_that_started_elsewhere():
    truth = np.arange(120, 180)  # the drive starts at vertex 120, the belief at vertex 0
    trace = markov_localize(VERTEX_S, np.ones(60), scores_at(truth), settings(mixing=1e-3))
    assert trace.vertex[0] == 0  # the prior wins at first
    found = int(np.argmax(trace.vertex == truth))
    assert 0 < found <= 10 and np.all(trace.vertex[found:] == truth[found:])
    # without mixing the belief can never reach vertices it gave no mass
    stuck = markov_localize(VERTEX_S, np.ones(60), scores_at(truth), settings(mixing=0.0))
    assert not np.any(stuck.vertex == truth)


def test_odometry_carries_the_estimate_through_frames_without_a_view():
    truth = np.arange(80)
    scores = scores_at(truth)
    scores[20:50] = 0.5  # 30 frames that match everything equally (night, glare)
    trace = markov_localize(VERTEX_S, np.full(80, 1.03), scores, settings())  # odometry 3 % long
    assert np.max(np.abs(trace.vertex[20:50] - truth[20:50])) <= 2
    assert list(trace.vertex[55:]) == list(truth[55:])


def test_bad_input_names_the_key():
    with pytest.raises(InputError, match=r"^place.localize.filter.floor: "):
        settings(floor=0.0)
    with pytest.raises(InputError, match=r"^place.localize.filter.mixing: "):
        settings(mixing=1.0)
    with pytest.raises(InputError, match=r"^scores: "):
        markov_localize(VERTEX_S, np.ones(5), np.zeros((5, M - 1)), settings())
    with pytest.raises(InputError, match=r"^map: "):
        markov_localize(np.array([]), np.ones(2), np.zeros((2, 0)), settings())
