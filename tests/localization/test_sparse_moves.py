"""The numbering of a step's distinct (group, cell) keys (``topoloc.localization.metric.sparse_moves.DistinctKeys``):
the keys of ``np.unique(keys, return_inverse=True)`` in some order, each key numbered by its place among them,
through slots up to ``SLOTS_MAX`` keys and by ``np.unique`` above."""

from __future__ import annotations

import numpy as np
import pytest

from topoloc.localization.metric import sparse_moves
from topoloc.localization.metric.sparse_moves import DistinctKeys


@pytest.mark.parametrize("slots_max", [1 << 24, 10])
def test_distinct_keys_are_np_uniques_each_numbered_by_its_place(monkeypatch, slots_max):
    monkeypatch.setattr(sparse_moves, "SLOTS_MAX", slots_max)
    distinct_keys = DistinctKeys(4 * 3 * 500)
    rng = np.random.default_rng(0)
    for size in (0, 1, 7, 3000):  # the slots reused from call to call
        keys = rng.integers(0, 4 * 3 * 500, size)
        keys[size // 2:] = keys[: size - size // 2]  # every key at least twice in the second half
        distinct, inverse = distinct_keys(keys)
        assert len(distinct) == len(set(distinct.tolist()))  # each key once
        np.testing.assert_array_equal(np.sort(distinct), np.unique(keys))
        np.testing.assert_array_equal(distinct[inverse], keys)
    assert (distinct_keys._slots is None) == (slots_max < 4 * 3 * 500)
