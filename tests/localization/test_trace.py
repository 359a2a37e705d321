"""A step's record of the metric filter's active cells (``topoloc.localization.metric.trace.ranked_cells``)."""

from __future__ import annotations

import numpy as np

from topoloc.localization.metric.trace import ranked_cells


def test_a_steps_record_ranks_each_filters_cells_by_mass_the_lowest_cell_of_a_tie_first():
    filt = np.array([2, 0, 2, 0, 2, 1, 0, 3])
    cell = np.array([7, 4, 3, 9, 5, 1, 2, 6])
    mass = np.array([0.2, 0.5, 0.4, 0.5, 0.4, 1.0, 0.0, 1.0])
    few = np.array([True, True, True, False])
    records = ranked_cells(filt, cell, mass, np.array([2, 0, 3, 1]), few, keep_top=3)
    assert [r.tolist() if r is not None else None for r in records] == [[3, 5, 7], [4, 9, 2], None, [1]]
    # a filter with more cells than keep_top keeps none
    assert ranked_cells(filt, cell, mass, np.array([2, 1]), few, keep_top=2)[0] is None
