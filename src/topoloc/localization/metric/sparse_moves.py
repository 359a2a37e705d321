"""What a step of the metric filter's sparse path needs (:meth:`topoloc.localization.metric.dense_filter.MetricFilter.update`):
the moves of some cells (rows of a transition matrix), and the distinct (group, cell) keys they land on, numbered."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

#: Most slots of :class:`DistinctKeys` (one per possible key): 64 MB; past it, ``np.unique``.
SLOTS_MAX = 1 << 24


def gather_rows(matrix: sp.csr_matrix, rows: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Entries of ``rows`` of a CSR matrix: (position in ``rows``, column, value)."""
    counts = matrix.indptr[rows + 1] - matrix.indptr[rows]
    owner = np.repeat(np.arange(len(rows)), counts)
    idx = np.repeat(matrix.indptr[rows], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
    return owner, matrix.indices[idx], matrix.data[idx]


class DistinctKeys:
    """``np.unique(keys, return_inverse=True)`` for keys in ``[0, size)``, but the distinct keys in no particular
    order: they are found and numbered through a slot per key, and not sorted (the sort took more than half the
    time, and no caller needs the order); past :data:`SLOTS_MAX` slots, ``np.unique`` itself."""

    def __init__(self, size: int) -> None:
        self.size = int(size)
        self._slots: NDArray[np.int32] | None = None  # allocated at the first call, reused after

    def __call__(self, keys: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.integer]]:
        """The distinct keys (each once, in no particular order), and the position of each key among them."""
        if self.size > SLOTS_MAX:
            return np.unique(keys, return_inverse=True)
        if self._slots is None:
            self._slots = np.empty(self.size, np.int32)  # half the memory traffic of int64 slots
        slots = self._slots
        index = np.arange(len(keys), dtype=np.int32)
        slots[keys] = index
        distinct = keys[slots[keys] == index]  # one entry per key: the one written last
        slots[distinct] = np.arange(len(distinct), dtype=np.int32)
        return distinct, slots[keys]
