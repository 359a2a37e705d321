"""The metric filter's path traced back (:meth:`topoloc.localization.metric.dense_filter.MetricFilter.path`): a
consistent cell sequence from a filter's record of its steps."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from topoloc.localization.metric.map_model import MetricModel

#: One step of a filter's record: direction, the odometry's yaw, the active cells by probability (None while many).
Step = tuple[int, float, NDArray[np.int64] | None]


def ranked_cells(filt: NDArray[np.int64], cell: NDArray[np.int64], mass: NDArray[np.float64], which: NDArray[np.int64],
                 few: NDArray[np.bool_], keep_top: int) -> list[NDArray[np.int64] | None]:
    """Per filter in ``which``, the cells of a belief given once per (``filt``, ``cell``) with their ``mass``, most
    probable first (the lowest cell of a tie first): a step's record; None for a filter not ``few`` (per filter) or
    with more than ``keep_top`` cells."""
    mine = few[filt]
    filt, cell, mass = filt[mine], cell[mine], mass[mine]
    order = np.lexsort((cell, -mass, filt))
    cell = cell[order]
    bounds = np.searchsorted(filt[order], np.stack([which, which + 1]))
    return [cell[a:z] if few[b] and z - a <= keep_top else None for b, a, z in zip(which.tolist(), *bounds.tolist())]


def trace_back(model: MetricModel, history: list[Step], offset: complex) -> NDArray[np.int64]:
    """A consistent cell sequence of the steps ``history``, from the last step's most probable cell (its first active
    cell) with the heading offset ``offset`` (``e^{i theta}``); all -1 when the last step kept no cells.

    At each earlier step the cell is one of those the transition leads from to the cell chosen after it: the most
    probable of them among the step's active cells where they were kept, else the likeliest by the move and by how
    its map heading plus the offset carried back along the path agrees with that step's yaw.
    """
    cells = np.full(len(history), -1, np.int64)
    if not history or history[-1][2] is None or not len(history[-1][2]):
        return cells
    cells[-1] = history[-1][2][0]
    for t in range(len(history) - 1, 0, -1):
        direction, _, _ = history[t]
        cols = model.forward_cols if direction > 0 else model.backward_cols
        sources = cols.indices[cols.indptr[cells[t]]:cols.indptr[cells[t] + 1]]
        moves = cols.data[cols.indptr[cells[t]]:cols.indptr[cells[t] + 1]]
        if len(sources) == 0:
            break
        kept = history[t - 1][2]
        ranked = np.flatnonzero((kept[:, None] == sources[None, :]).any(axis=1)) if kept is not None else np.zeros(0, np.int64)
        if len(ranked):
            cells[t - 1] = kept[ranked[0]]
        else:
            agree = (np.exp(1j * history[t - 1][1]) * model.unheading[sources] * np.conj(offset)).real
            score = np.log(moves) + model.kappa_obs[sources] * (agree - 1.0)  # the move and the heading
            cells[t - 1] = sources[int(np.argmax(score))]
        sample = np.exp(1j * history[t - 1][1]) * model.unheading[cells[t - 1]]
        offset = (0.9 * offset + 0.1 * sample) / abs(0.9 * offset + 0.1 * sample)  # follows slow drift back
    return cells
