"""The top places of a belief over cells of roads, for every filter of a bank at once: the ``top_places`` of the
metric filter (:mod:`topoloc.localization.metric`) and of the token HMM (:mod:`topoloc.localization.hmm`, and so
``rnn_filter``); see :class:`topoloc.localizer.RankedFilter`.

A place is a road (undirected edge): its probability is the belief's mass on the road's cells (both directions),
its position the road's cell of most mass (a filter split into scale classes holds a cell once per class: the
classes' entries of a cell add up). Of every filter the :data:`CANDIDATES` times ``k`` most probable roads are
ranked, places within ``merge_m`` metres of a more probable one merged into it (:func:`topoloc.localizer.merge_places`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from topoloc.localizer import Place, merge_sorted

#: Roads ranked per place asked for (merging may fold several into one place).
CANDIDATES = 4


Distinct = Callable[[NDArray[np.int64]], tuple[NDArray[np.int64], NDArray[np.integer]]]


def cell_sums(owner: NDArray[np.int64], cell: NDArray[np.int64], weight: NDArray, cells: int,
              distinct: Distinct | None = None) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """The entries of one (filter, cell) added up (a filter split into scale classes holds a cell once per class):
    the distinct (filter, cell) pairs and their mass. ``distinct`` finds the distinct keys ``filter * cells + cell``
    and numbers them as ``np.unique(keys, return_inverse=True)`` does (the default, in order of key), for keys
    below ``filters`` times ``cells`` (:class:`topoloc.localization.metric.sparse_moves.DistinctKeys`: faster, in
    no particular order)."""
    keys = owner * cells + cell
    owned, where = distinct(keys) if distinct is not None else np.unique(keys, return_inverse=True)
    return owned // cells, owned % cells, np.bincount(where, weights=weight, minlength=len(owned))


def cells_of_most_mass(owner: NDArray[np.int64], cell: NDArray[np.int64], mass: NDArray, cell_edge: NDArray[np.int64],
                       filters: int, roads: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Per (filter, road), at ``filter * roads + road``: the most ``mass`` on one cell of the road and that cell, the
    lowest of a tie; -1 and 0 where none of the pairs lies on the road. Each (``owner``, ``cell``) pair appears
    once (:func:`cell_sums`)."""
    key = owner * roads + cell_edge[cell]
    best = np.full(filters * roads, -1.0)
    np.maximum.at(best, key, mass)
    hit = np.flatnonzero(mass == best[key])
    hit = hit[np.argsort(-cell[hit], kind="stable")]  # written from the highest cell down: the lowest of a tie wins
    best_cell = np.zeros(filters * roads, np.int64)
    best_cell[key[hit]] = cell[hit]
    return best, best_cell


def belief_places(owner: NDArray[np.int64], cell: NDArray[np.int64], weight: NDArray, cell_edge: NDArray[np.int64],
                  cell_xy: NDArray[np.float64], filters: int, roads: int, k: int, merge_m: float = 0.0,
                  which: NDArray[np.int64] | None = None, shift_m: float = 0.0,
                  cell_direction: NDArray[np.float64] | None = None, summed: bool = False) -> list[list[Place]]:
    """Per filter of ``filters`` (or of those in ``which``, in its order), its top ``k`` places, from the belief's
    entries: the filter that ``owner``\\ s each entry, its ``cell`` and ``weight`` (entries of one cell may repeat:
    they add up); ``cell_edge`` and ``cell_xy`` give each cell's road and position on a map of ``roads`` roads.
    A place's position is its road's cell of most mass, moved ``shift_m`` metres along that cell's unit
    ``cell_direction`` ``(cells, 2)`` (the distance driven since the belief's last step). With ``summed`` the
    entries are already one per (filter, cell) (:func:`cell_sums`), and not summed again."""
    owner, cell = np.asarray(owner, np.int64), np.asarray(cell, np.int64)
    weight = np.asarray(weight)
    key = owner * roads + cell_edge[cell]
    marginal = np.bincount(key, weights=weight, minlength=filters * roads).reshape(filters, roads)
    rows = np.arange(filters) if which is None else np.asarray(which, np.int64)
    marginal = marginal[rows]
    m = min(roads, CANDIDATES * max(1, int(k)))
    top = np.argpartition(-marginal, m - 1, axis=1)[:, :m] if m < roads else np.tile(np.arange(roads), (len(rows), 1))
    prob = np.take_along_axis(marginal, top, axis=1)
    order = np.argsort(-prob, axis=1, kind="stable")  # most probable first
    top, prob = np.take_along_axis(top, order, axis=1), np.take_along_axis(prob, order, axis=1)
    wanted = np.zeros(filters * roads, bool)
    wanted[(rows[:, None] * roads + top).ravel()] = True
    mine = np.flatnonzero(wanted[key] & (weight > 0))
    pairs = (owner[mine], cell[mine], weight[mine])
    _, best_cell = cells_of_most_mass(*(pairs if summed else cell_sums(*pairs, len(cell_xy))), cell_edge,
                                      filters, roads)
    chosen = best_cell[rows[:, None] * roads + top]
    xy = cell_xy[chosen] if cell_direction is None or shift_m == 0 else cell_xy[chosen] + shift_m * cell_direction[chosen]
    xy = np.where((prob > 0)[..., None], xy, np.nan)
    states, probs, xs, ys = top.tolist(), prob.tolist(), xy[..., 0].tolist(), xy[..., 1].tolist()
    return [merge_sorted(states[b], probs[b], xs[b], ys[b], k, merge_m) for b in range(len(rows))]
