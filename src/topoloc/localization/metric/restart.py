"""Finding the track again: a filter that has lost the track it held races a fresh filter started after the loss.

A filter more likely off the map than on it (after a parking lot, a road the map lacks) takes mass back onto the map
with ``enter_prob`` per step, spread over every cell. That mass is tiny beside the stale belief it kept, so after the
vehicle returns onto the map the filter may stay off the map, or settle, sure, on a look-alike of where it left
(``bench_filter_recovery``). Re-seeding the lost filter at once does not help: the fresh belief then sees the stretch
the map cannot explain, and settles on a look-alike of it.

:class:`RestartingFilter` keeps, for each filter (a *main* filter), a *challenger* slot in the same bank of
:class:`~topoloc.localization.metric.city_filter.CityFilter` filters:

* once the main filter has been sure (confidence >= ``confidence``) and is then lost (off-map probability >= 0.5),
  a challenger starts, uniform over the map, as a fresh start would;
* a challenger that is itself lost starts again: it saw the stretch the map cannot explain, so the challenger that
  is left is the one started after the last such stretch;
* a challenger that has stayed sure for ``hold_m`` (a fresh belief is often sure of a look-alike for a while) ends
  the race: where both are sure of one road the challenger stops; otherwise, where it explains the headings seen
  since it started better than the main filter by ``margin`` (natural log of the likelihood ratio), its belief
  becomes the main filter's (the slots swap). Until then the answers stay the main filter's.

The answers and the paths are the main filters' (a path traced back joins the old belief's path before the swap
to the challenger's after it). A drive that never loses its track never starts a challenger, so its answers are
those of the plain filter, bit for bit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from topoloc.localization.metric.city_filter import CityFilter
from topoloc.localization.metric.dense_filter import Estimate
from topoloc.localization.metric.map_model import MetricModel
from topoloc.localizer import Place

LOST_OFFMAP = 0.5  # as the filters' own re-entry (dense_filter._reenter): more likely off the map than on it
TRACK_CHECK_STEPS = 5  # whether a filter has held a track yet is checked every this many steps (it costs the roads' marginals)


class RestartingFilter:
    """``filters`` metric filters, each with a challenger that restarts it after a lost track (module docstring)."""

    def __init__(self, fine: MetricModel, coarse: MetricModel | None, filters: int = 1, confidence: float = 0.9,
                 margin: float = 3.0, hold_m: float = 100.0) -> None:
        self.filters, self.confidence, self.margin = int(filters), float(confidence), float(margin)
        self.bank = CityFilter(fine, coarse, 2 * self.filters)
        self.model, self.grid = fine, fine.grid
        self.slot = np.arange(self.filters)  # the bank slot of each main filter; its challenger has the other one
        self.spare = self.slot + self.filters
        self.had_track = np.zeros(self.filters, bool)
        self.racing = np.zeros(self.filters, bool)
        self.base = np.zeros(self.filters)  # the main filter's evidence when its challenger started
        self.sure_steps = np.zeros(self.filters, np.int64)  # steps the challenger has been sure in a row
        self.hold_steps = max(1, int(round(float(hold_m) / fine.settings.cell_m)))
        self.prefix: list[list[NDArray[np.int64]]] = [[] for _ in range(self.filters)]
        self.restarts = np.zeros(self.filters, np.int64)  # challengers started, per main filter
        self.swaps = np.zeros(self.filters, np.int64)  # challengers that took over, per main filter
        self._answers: list[Estimate] | None = None
        self.age = np.zeros(self.filters, np.int64)  # steps since each main filter's start

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells

    def start(self, which: int | NDArray[np.int64] | None = None) -> None:
        """(Re)start main filters ``which`` (default: all), uniform over the map, with no challenger."""
        which = np.arange(self.filters) if which is None else np.atleast_1d(np.asarray(which, np.int64))
        self.bank.stop(self.spare[which])
        self.bank.start(self.slot[which])
        self.had_track[which] = False
        self.racing[which] = False
        self.age[which] = 0
        for b in which:
            self.prefix[int(b)] = []
        self._answers = None

    def update(self, direction: int, yaw: float) -> None:
        """One step for every running filter and challenger, then the race of each lost track (module docstring)."""
        self.bank.update(direction, yaw)
        self._answers = None
        running = self.bank.running()[self.slot]
        self.age[running] += 1
        # each filter's own step count, so that a filter in a bank of many starts is answered as if alone
        check = running & ~self.had_track & (self.age % TRACK_CHECK_STEPS == 0)
        if not check.any() and not (running & self.racing).any() and not self._any_lost(running):
            return
        edge, confidence, offmap = self.bank.roads()
        evidence = self.bank.evidence()
        for b in np.flatnonzero(running):
            main, rival = int(self.slot[b]), int(self.spare[b])
            if check[b] and confidence[main] >= self.confidence:
                self.had_track[b] = True
            if not self.racing[b]:
                if self.had_track[b] and offmap[main] >= LOST_OFFMAP:
                    self._challenge(b)
            elif offmap[rival] >= LOST_OFFMAP:
                self._challenge(b)
            elif confidence[rival] < self.confidence:
                self.sure_steps[b] = 0
            elif (sure := self.sure_steps[b] + 1) < self.hold_steps:
                self.sure_steps[b] = sure
            elif edge[main] == edge[rival] and confidence[main] >= self.confidence:
                self.bank.stop(rival)  # both sure of one road: the track was not lost
                self.racing[b] = False
            elif evidence[rival] - (evidence[main] - self.base[b]) > self.margin:
                self._swap(b)
                self.racing[b] = False

    def _any_lost(self, running: NDArray[np.bool_]) -> bool:
        """Whether a running main filter that has held a track is more likely off the map than on it (cheap)."""
        offmap = self.bank.fine.offmap
        if self.bank.coarse is not None:
            offmap = np.where(self.bank.in_coarse, self.bank.coarse.offmap, offmap)
        return bool((running & self.had_track & (offmap[self.slot] >= LOST_OFFMAP)).any())

    def _challenge(self, b: int) -> None:
        self.bank.start(self.spare[b])
        self.sure_steps[b] = 0
        self.base[b] = self.bank.evidence()[self.slot[b]]
        self.racing[b] = True
        self.restarts[b] += 1

    def _swap(self, b: int) -> None:
        """The challenger of main filter ``b`` becomes it; the old belief stops, its path before the swap kept."""
        old, new = int(self.slot[b]), int(self.spare[b])
        path = self.bank.path(old)
        self.prefix[b].append(path[:len(path) - len(self.bank.fine.history[new])])
        self.bank.stop(old)
        self.slot[b], self.spare[b] = new, old
        self.swaps[b] += 1

    # -- answers: the main filters' ----------------------------------------------------------------------------

    def answers(self) -> list[Estimate]:
        """Per main filter: the road of largest probability, its cell of most mass, that probability."""
        if self._answers is None:
            self._answers = self.bank.answers()
        return [self._answers[int(s)] for s in self.slot]

    def answer(self, which: int = 0) -> Estimate:
        """The answer of main filter ``which``."""
        return self.answers()[which]

    def places(self, k: int, merge_m: float = 0.0, which: NDArray[np.int64] | None = None,
               shift_m: float = 0.0) -> list[list[Place]]:
        """Per main filter (or per main filter in ``which``), its ``k`` most probable places, ``shift_m`` metres on."""
        return self.bank.places(k, merge_m, self.slot if which is None else self.slot[np.asarray(which, np.int64)], shift_m)

    def top_places(self, k: int, merge_m: float = 0.0, which: int = 0, shift_m: float = 0.0) -> list[Place]:
        """The ``k`` most probable places of main filter ``which``."""
        return self.places(k, merge_m, shift_m=shift_m)[which]

    def path(self, which: int = 0) -> NDArray[np.int64]:
        """Main filter ``which``'s path traced back (fine cells, -1 where unknown), across its swaps."""
        return np.concatenate(self.prefix[which] + [self.bank.path(int(self.slot[which]))])

    def road_marginals(self, which: int = 0) -> NDArray[np.float64]:
        """Main filter ``which``'s probability of each undirected road."""
        return self.bank.road_marginals(int(self.slot[which]))

    def belief(self, which: int = 0) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """Main filter ``which``'s belief: map positions of its cells, their probabilities, the off-map probability."""
        return self.bank.belief(int(self.slot[which]))
