"""The metric filter's numbering of a step's distinct (group, cell) keys (``MetricFilter._unique``): the same as
``np.unique(keys, return_inverse=True)``, through slots below ``SLOTS_MAX`` keys and by ``np.unique`` above."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from topoloc.localization.metric import dense_filter
from topoloc.localization.metric.dense_filter import MetricFilter


@pytest.mark.parametrize("slots_max", [1 << 24, 10])
def test_distinct_keys_are_numbered_as_np_unique(monkeypatch, slots_max):
    monkeypatch.setattr(dense_filter, "SLOTS_MAX", slots_max)
    bank = SimpleNamespace(filters=4, classes=3, num_cells=500, _slots=None)
    rng = np.random.default_rng(0)
    for size in (0, 1, 7, 3000):
        keys = rng.integers(0, 4 * 3 * 500, size)
        keys[size // 2:] = keys[: size - size // 2]  # every key at least twice in the second half
        distinct, inverse = MetricFilter._unique(bank, keys)
        expected, expected_inverse = np.unique(keys, return_inverse=True)
        np.testing.assert_array_equal(distinct, expected)
        np.testing.assert_array_equal(inverse, expected_inverse)
    assert (bank._slots is None) == (slots_max < 4 * 3 * 500)
