"""The metric filter at city scale: coarse cells while the belief is broad, the full grid once it is not.

On a city map (Heidelberg: 1.3 million cells of 2 m) a belief spread over the whole map costs about 0.2 s
per 2 m step: slower than a car drives. A filter therefore starts on a *coarse* model of the same map
(:class:`~topoloc.localization.metric.map_model.MetricModel` with cells ``coarse_factor`` times longer, on the same
roads, so that every fine cell lies in one coarse cell): a coarse step is taken every ``coarse_factor``
fine steps (net, so reversing counts back), with the yaw at that moment; ``coarse_factor`` 4 costs about
16 times less per metre. The coarse model may be more tolerant (heading spread and turn spread times
``coarse_spread``, the distance jitter scaled to the same variance per metre, no scale classes, no U-turns across a
median: a tight U-turn's coarse cells stand for them, at the share of both; no wide ways: the tight turns' cells
and the road's middle stand for them, so that they cost nothing while the belief is broad); with one
observation per coarse cell it already tells roads apart less sharply per metre than the full grid, so the
default spread is 1 and the coarse phase is kept short. Once the coarse belief of a filter holds at most
``coarse_handoff_cells`` positions (counted in fine cells), or ``coarse_handoff_share`` of the map's cells where
that is fewer, it is handed to the fine filter at a coarse
step: each coarse entry's mass is spread over the fine cells it covers (by their length), with its heading
offset belief; from there the filter is the dense one (:class:`~topoloc.localization.metric.dense_filter.MetricFilter`).
A fine filter that gets lost (more likely off the map than on it) goes back to the coarse phase with its
belief summed into coarse cells, and the coarse filter spreads the returning mass over the map.

Maps of at most ``coarse_min_cells`` cells (every map before city scale) never use the coarse phase: the
answers are the dense filter's, bit for bit. :class:`CityFilter` has the interface of
:class:`MetricFilter` that the localizer uses (the :class:`topoloc.localizer.Filter` methods ``start``,
``update``, ``answer`` and ``path``, and ``answers``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from topoloc.localization.metric.cell_grid import CellGrid
from topoloc.localization.metric.dense_filter import COMPLEX, REAL, TINY, Estimate, MetricFilter
from topoloc.localization.metric.map_model import MetricModel, MetricSettings
from topoloc.localization.metric.von_mises import concentration, resultant_length
from topoloc.localizer import Place


def coarse_settings(settings: MetricSettings) -> MetricSettings:
    """The settings of the coarse model that goes with ``settings`` (see the module docstring)."""
    k = settings.coarse_factor
    return dataclasses.replace(settings, cell_m=settings.cell_m * k, step_jitter=settings.step_jitter / k,
                               heading_sigma_deg=settings.coarse_spread * settings.heading_sigma_deg,
                               turn_sigma_share=settings.coarse_spread * settings.turn_sigma_share, scale_classes=1, coarse_factor=1,
                               lateral_offset_m=0.0, u_turn_gap_m=0.0, wide_zone_m=0.0)


def coarse_positions(fine: CellGrid, coarse: CellGrid) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Per fine cell, the coarse chain at its place on the map and the metres driven along it to there. The coarse
    chains are the plain ones (:attr:`Chains.plain_turn`): a fine turn lies on the coarse turn of its way (a U-turn
    across on its tight U-turn, spread over it; a wide turn where it is inside the tight turn's zones), the rest on
    the middle of its road."""
    fc, cc = fine.chains, coarse.chains
    if fc.plain_turn is None:  # the same chains, of the same lengths
        return fine.chain, fine.offset
    turns = np.flatnonzero(cc.second_state >= 0)  # the plain turns, in their order
    middles = np.flatnonzero(cc.second_state < 0)
    middle_of = np.full(fine.states.num_states, -1, np.int64)
    middle_of[cc.first_state[middles]] = middles
    way = fc.plain_turn[fine.chain]
    turn = turns[np.maximum(way, 0)]
    on_map = fine.offset * (1.0 if fc.stretch is None else fc.stretch[fine.chain])
    at = cc.split[turn] + on_map - fc.split[fine.chain]  # map metres along the coarse turn, the node at the same place
    on_turn = (way >= 0) & (at >= -TINY) & (at <= cc.map_length[turn] + TINY)
    middle = middle_of[fine.state]
    if (middle[~on_turn] < 0).any():
        raise ValueError("a fine cell outside every turn lies on a road without a middle among the coarse chains")
    chain = np.where(on_turn, turn, middle)
    along = np.where(on_turn, at, fine.state_offset - cc.first_from[np.maximum(middle, 0)])
    stretch = 1.0 if cc.stretch is None else cc.stretch[chain]
    return chain, np.clip(along / stretch, 0.0, cc.length[chain])


def uses_coarse(settings: MetricSettings, fine_cells: int) -> bool:
    """Whether a map of ``fine_cells`` cells is run with a coarse phase."""
    return settings.coarse_factor > 1 and fine_cells > settings.coarse_min_cells


class CityFilter:
    """Filters of one drive's starts, each on the coarse model while broad and on the fine one after."""

    def __init__(self, fine: MetricModel, coarse: MetricModel | None, filters: int = 1) -> None:
        self.model, self.grid, self.filters = fine, fine.grid, int(filters)
        self.fine = MetricFilter(fine, self.filters)
        self.coarse = MetricFilter(coarse, self.filters) if coarse is not None else None
        self.in_coarse = np.zeros(self.filters, bool)
        self._coarse_answers: list[Estimate] | None = None  # the coarse belief changes once per coarse step only
        if coarse is None:
            return
        self.factor = int(fine.settings.coarse_factor)
        settings = fine.settings
        handoff = min(settings.coarse_handoff_cells, settings.coarse_handoff_share * fine.num_cells)  # in fine cells
        self.handoff = max(1, int(handoff) // self.factor)  # in coarse entries
        self.level, self.coarse_level = 0, 0  # net fine steps driven, and net coarse steps
        fg, cg = fine.grid, coarse.grid
        chain, offset = coarse_positions(fg, cg)
        index = np.floor(offset / np.maximum(cg.cell_len[chain], TINY)).astype(np.int64)
        count = cg.base[chain + 1] - cg.base[chain]
        self.coarse_of = cg.base[chain] + np.clip(index, 0, np.maximum(count - 1, 0))  # fine cell -> coarse cell
        self.order = np.argsort(self.coarse_of, kind="stable")  # fine cells by coarse cell: a CSR list
        self.ptr = np.searchsorted(self.coarse_of[self.order], np.arange(cg.num_cells + 1))
        # by length, times the chain's weight where it branches off (an approach against the wide turns off it)
        way = 1.0 if fg.chains.weight is None else fg.chains.weight[fg.chain]
        share = way * fg.cell_len[fg.chain] / np.maximum(cg.cell_len[cg.chain[self.coarse_of]], TINY)
        self.share = (share / np.maximum(np.bincount(self.coarse_of, weights=share, minlength=cg.num_cells), TINY)[self.coarse_of])
        centre = np.abs(offset - cg.offset[self.coarse_of])  # the fine cell nearest each coarse cell's centre
        best = np.lexsort((centre, self.coarse_of))
        self.fine_of = np.full(cg.num_cells, -1, np.int64)
        self.fine_of[self.coarse_of[best[::-1]]] = best[::-1]

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells

    # -- life cycle ------------------------------------------------------------------------------------------

    def start(self, which: int | NDArray[np.int64] | None = None) -> None:
        """(Re)start filters ``which`` (default: all), uniform over the map; on a city map in the coarse phase."""
        which = np.arange(self.filters) if which is None else np.atleast_1d(np.asarray(which, np.int64))
        if self.coarse is None:
            self.fine.start(which)
            return
        self.fine.stop(which)
        self.fine.evidence[which] = 0.0
        for b in which:
            self.fine.history[int(b)] = []
        self.coarse.start(which)
        self.in_coarse[which] = True
        self._coarse_answers = None

    def stop(self, which: int | NDArray[np.int64]) -> None:
        """Stop filters ``which`` (no entries, no steps; their history stays)."""
        which = np.atleast_1d(np.asarray(which, np.int64))
        self.fine.stop(which)
        if self.coarse is not None:
            self.coarse.stop(which)
            self.in_coarse[which] = False
            self._coarse_answers = None

    def evidence(self) -> NDArray[np.float64]:
        """Per filter, the log-likelihood of the yaws seen since its start, per fine step: a coarse step's term
        counts for the ``coarse_factor`` fine steps it stands for, so that a filter that spent part of a stretch on
        coarse cells is weighed on the same footing as one that spent it on the full grid (the restart's race)."""
        if self.coarse is None:
            return self.fine.evidence
        return self.fine.evidence + self.factor * self.coarse.evidence

    def running(self) -> NDArray[np.bool_]:
        """Per filter, whether it takes steps (in either phase)."""
        return self.fine.running | (self.coarse.running if self.coarse is not None else False)

    def _to_fine(self, b: int) -> None:
        """Hand filter ``b``'s coarse belief to the fine filter (mass spread over the fine cells it covers)."""
        last_yaw = float(self.coarse.last_yaw[b])
        offmap = float(self.coarse.offmap[b])
        cell, weight, kappa, mean = self.coarse.take(b)
        counts = self.ptr[cell + 1] - self.ptr[cell]
        owner = np.repeat(np.arange(len(cell)), counts)
        idx = np.repeat(self.ptr[cell], counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        fine = self.order[idx]
        self.fine.seed(b, fine, weight[owner] * self.share[fine], kappa[owner], mean[owner], offmap, last_yaw)
        self.in_coarse[b] = False
        self._coarse_answers = None

    def _to_coarse(self, b: int) -> None:
        """Send a lost fine filter ``b`` back to the coarse phase (its belief summed into coarse cells)."""
        history = self.fine.history[b]
        offmap, last_yaw = float(self.fine.offmap[b]), float(self.fine.last_yaw[b])
        cell, weight, kappa, mean = self.fine.take(b)
        self.fine.history[b] = history
        n = self.coarse.num_cells
        coarse = self.coarse_of[cell]
        total = np.bincount(coarse, weights=weight, minlength=n)
        flow = weight * resultant_length(kappa) * mean
        resultant = np.bincount(coarse, weights=flow.real, minlength=n) + 1j * np.bincount(coarse, weights=flow.imag, minlength=n)
        cells = np.flatnonzero(total > 0)
        length = np.abs(resultant[cells])
        self.coarse.seed(b, cells, total[cells], concentration(length / total[cells]).astype(REAL),
                         np.where(length > 0, resultant[cells] / np.maximum(length, TINY), 1.0).astype(COMPLEX),
                         offmap, last_yaw)
        self.in_coarse[b] = True
        self._coarse_answers = None

    # -- one step --------------------------------------------------------------------------------------------

    def update(self, direction: int, yaw: float) -> None:
        """One fine step (``cell_m`` forward or back, the odometry's ``yaw``) for every running filter."""
        if self.coarse is None:
            self.fine.update(direction, yaw)
            return
        for b in np.flatnonzero(self.fine.running & (self.fine.offmap >= 0.5) & (self.fine.settings.enter_prob > 0)):
            self._to_coarse(int(b))
        self.level += 1 if direction > 0 else -1
        coarse_step = 0
        if self.level >= (self.coarse_level + 1) * self.factor:
            coarse_step = 1
        elif self.level <= (self.coarse_level - 1) * self.factor:
            coarse_step = -1
        if self.fine.running.any():
            self.fine.update(direction, yaw)
        for b in np.flatnonzero(self.in_coarse):
            self.fine.history[int(b)].append((int(direction), float(yaw), None))
        if coarse_step:  # after the fine step: a belief handed over now stands for the position after this step
            self.coarse_level += coarse_step
            if self.coarse.running.any():
                self.coarse.update(coarse_step, yaw)
                self._coarse_answers = None
            counts = np.bincount(self.coarse.group // self.coarse.classes, minlength=self.filters)
            for b in np.flatnonzero(self.in_coarse & self.coarse.running & (counts <= self.handoff)):
                self._to_fine(int(b))

    # -- answers ---------------------------------------------------------------------------------------------

    def answers(self) -> list[Estimate]:
        """Per filter: the road of largest probability, its cell of most mass (a fine cell), that probability."""
        out = self.fine.answers()
        if self.coarse is None or not self.in_coarse.any():
            return out
        if self._coarse_answers is None:
            self._coarse_answers = self.coarse.answers()
        coarse = self._coarse_answers
        for b in np.flatnonzero(self.in_coarse):
            est = coarse[b]
            out[b] = Estimate(est.edge, int(self.fine_of[est.cell]) if est.cell >= 0 else -1, est.xy, est.confidence, est.offmap)
        return out

    def answer(self, which: int = 0) -> Estimate:
        """The answer of filter ``which``."""
        return self.answers()[which]

    def road_marginals(self, which: int = 0) -> NDArray[np.float64]:
        """Filter ``which``'s probability of each undirected road (of the coarse belief while in the coarse phase)."""
        bank = self.coarse if self.coarse is not None and self.in_coarse[which] else self.fine
        return bank.edge_marginals()[which]

    def roads(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Per filter, the road of largest probability, that probability and the off-map probability (cheaper than
        :meth:`answers`: no cells)."""
        edge, confidence = self.fine.roads()
        offmap = self.fine.offmap.copy()
        if self.coarse is not None and self.in_coarse.any():
            coarse_edge, coarse_confidence = self.coarse.roads()
            edge = np.where(self.in_coarse, coarse_edge, edge)
            confidence = np.where(self.in_coarse, coarse_confidence, confidence)
            offmap = np.where(self.in_coarse, self.coarse.offmap, offmap)
        return edge, confidence, offmap

    def places(self, k: int, merge_m: float = 0.0, which: NDArray[np.int64] | None = None,
               shift_m: float = 0.0) -> list[list[Place]]:
        """Per filter (or per filter in ``which``), its ``k`` most probable places (of the coarse belief while in the
        coarse phase), ``shift_m`` metres on (:meth:`DenseFilter.places`)."""
        which = np.arange(self.filters) if which is None else np.asarray(which, np.int64)
        out = self.fine.places(k, merge_m, which, shift_m)
        coarse = np.flatnonzero(self.in_coarse[which]) if self.coarse is not None else np.zeros(0, np.int64)
        if len(coarse):
            for i, places in zip(coarse, self.coarse.places(k, merge_m, which[coarse], shift_m)):
                out[i] = places
        return out

    def top_places(self, k: int, merge_m: float = 0.0, which: int = 0, shift_m: float = 0.0) -> list[Place]:
        """The ``k`` most probable places of filter ``which`` (:class:`topoloc.localizer.RankedFilter`)."""
        return self.places(k, merge_m, shift_m=shift_m)[which]

    def path(self, which: int = 0) -> NDArray[np.int64]:
        """Filter ``which``'s path traced back (fine cells; -1 throughout while it is still in the coarse phase)."""
        if self.in_coarse[which]:
            return np.full(len(self.fine.history[which]), -1, np.int64)
        return self.fine.path(which)

    def belief(self, which: int = 0) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """Filter ``which``'s belief: map positions (n, 2) of its cells, their probabilities, the off-map probability."""
        bank = self.coarse if self.in_coarse[which] else self.fine
        mine = bank.group // bank.classes == which
        cells, inverse = np.unique(bank.cell[mine], return_inverse=True)
        weight = np.bincount(inverse, weights=bank.weight[mine].astype(np.float64), minlength=len(cells))
        return bank.grid.xy[cells], weight, float(bank.offmap[which])
