"""The metric filter's lateral-offset classes (``localization.metric.lateral_offset_m``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from localization_helpers import irregular_grid

from topoloc.config import load
from topoloc.localization.connectivity import directed_edges
from topoloc.localization.metric.city_filter import coarse_settings
from topoloc.localization.metric.dense_filter import MetricFilter
from topoloc.localization.metric.map_model import MetricModel, MetricSettings


def model_with(offset_m: float) -> MetricModel:
    graph, _ = irregular_grid()
    settings = dataclasses.replace(MetricSettings.from_conf(load(None)["localization"]["metric"]), lateral_offset_m=offset_m)
    return MetricModel(graph, directed_edges(graph, settings.u_turns), settings)


def test_without_an_offset_the_classes_are_the_scale_classes():
    model = model_with(0.0)
    np.testing.assert_array_equal(model.class_scale, model.scales)
    np.testing.assert_array_equal(model.class_offset_m, 0.0)
    np.testing.assert_allclose(model.class_prior, model.scale_prior)


def test_two_offset_classes_as_likely_as_the_largest_scale_error():
    model = model_with(2.0)
    k = len(model.scales)
    np.testing.assert_array_equal(model.class_offset_m, [0.0] * k + [-2.0, 2.0])
    np.testing.assert_array_equal(model.class_scale[k:], 0.0)  # no scale error besides the offset
    assert model.class_prior.sum() == pytest.approx(1.0)
    assert model.class_prior[k] == pytest.approx(model.class_prior[0]) == pytest.approx(model.class_prior[-1])
    assert MetricFilter(model).center == k // 2  # a fresh belief is still the nominal class


def test_an_offset_class_moves_less_on_the_outside_of_a_turn():
    model = model_with(2.0)  # 2 m cells: one cell per radian either way
    k = len(model.scales)
    bank = MetricFilter(model)
    bank.start()
    bank.split[:] = True
    bank.last_yaw[:] = 0.0
    moves = bank._moves(0.5)  # half a radian left this step
    left, right = k, k + 1
    # whole cells, the nearest to where each class is: inside 1.5 cells of the map per step, outside half a cell
    assert moves[left] == 2 and bank.ahead[left] == pytest.approx(-0.5)
    assert moves[right] == 1 and bank.ahead[right] == pytest.approx(-0.5)
    np.testing.assert_array_equal(moves[:k], np.floor(1.0 / (1.0 + model.scales) + 0.5))  # the scale classes as before
    moves = bank._moves(0.5 - 0.5)  # straight on: every class one cell, the offset's lead kept
    assert moves[left] == 1 and moves[right] == 1
    assert bank.ahead[left] == pytest.approx(-0.5) and bank.ahead[right] == pytest.approx(-0.5)
    bank.last_yaw[:], bank.ahead[:] = 0.0, 0.0
    moves = bank._moves(-0.5)  # a right turn: the other way round
    assert moves[left] == 1 and moves[right] == 2 and bank.ahead[right] == pytest.approx(-0.5)


def test_a_belief_that_has_not_split_moves_one_cell_whatever_the_turn():
    bank = MetricFilter(model_with(2.0))
    bank.start()
    bank.last_yaw[:] = 0.0
    np.testing.assert_array_equal(bank._moves(1.0), 1)


def test_the_coarse_cells_of_a_city_map_have_no_offset_classes():
    settings = dataclasses.replace(MetricSettings.from_conf(load(None)["localization"]["metric"]), lateral_offset_m=3.0)
    assert coarse_settings(settings).lateral_offset_m == 0.0
