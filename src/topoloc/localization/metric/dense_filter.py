"""The belief of the metric filter (:mod:`topoloc.localization.metric`), for one or many starts of a drive.

A belief is a set of *entries* (in no particular order): a group, a cell, its probability and its heading-offset
belief (von Mises: mean and concentration), kept only where the probability is at least ``prune`` times the
largest of its filter. Several *filters* (the starts of a multi-start evaluation) share every step, so its cost
is paid once per step, not once per start. Within a filter, once the belief is no longer spread over much of the map, it splits into
``scale_classes`` *groups*, one per odometry scale error in ``[-scale_error_max, scale_error_max]``: a group
with scale error ``s`` moves ``1 / (1 + s)`` cells per step on average (an extra or a skipped move now and
then), so the group whose lengths agree with the map's wins at the turns, and a systematic scale error of
the odometry no longer makes a look-alike road fit better than the true one. With ``lateral_offset_m`` two more
groups drive that far left and right of the lane: they move less along the map on the outside of a turn and more on
its inside. A lost filter (more likely off the map than on it) merges its groups again and takes back mass spread
over the whole map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from topoloc.localization.metric.map_model import MetricModel
from topoloc.localization.metric.sparse_moves import DistinctKeys, gather_rows
from topoloc.localization.metric.trace import Step, ranked_cells, trace_back
from topoloc.localization.metric.von_mises import concentration, resultant_length
from topoloc.localization.places import belief_places, cell_sums, cells_of_most_mass
from topoloc.localizer import Place

TWO_PI = 2.0 * math.pi
TINY = float(np.finfo(np.float32).tiny)
#: Precision of the belief: single precision is ample for probabilities renormalized every step and for headings
#: (a cosine to 6e-8), and makes the elementwise work of a step three to four times faster than double.
#: (The weights turn double where a filter splits into its scale classes: :meth:`MetricFilter._split`.)
REAL, COMPLEX = np.float32, np.complex64
#: At most this many entries when a filter splits into its scale classes (maps of up to 131,072 cells split at a
#: 32nd of the map; a city map's split belief would otherwise hold hundreds of thousands of entries).
SPLIT_MAX = 4096

@dataclass
class Estimate:
    """A filter's answer after a step: road, cell, map position, confidence, off-map probability."""

    edge: int
    cell: int
    xy: NDArray[np.float64]
    confidence: float
    offmap: float


class MetricFilter:
    """The metric filter's beliefs for ``filters`` starts of one drive (see the module docstring).

    :meth:`start` (re)starts filters, :meth:`update` takes one step for every running filter,
    :meth:`answer` gives a filter's answer (:meth:`answers` every filter's) and :meth:`path` its path traced back
    (the methods of :class:`topoloc.localizer.Filter`, for many filters at once).
    """

    def __init__(self, model: MetricModel, filters: int = 1, keep_top: int = 512) -> None:
        self.model, self.settings, self.grid = model, model.settings, model.grid
        self.filters, self.prune, self.keep_top = int(filters), model.settings.prune, keep_top
        self.classes = len(model.class_scale)
        self.center = len(model.scales) // 2
        self.step_cells = 1.0 / (1.0 + model.class_scale)  # cells a group of each class moves per step
        self.offset_cells = model.class_offset_m / model.settings.cell_m  # cells fewer per radian turned left
        groups = self.filters * self.classes
        self.group = np.zeros(0, np.int64)  # group of each entry: filter * classes + class
        self.cell = np.zeros(0, np.int64)
        self.weight = np.zeros(0, REAL)
        self.kappa = np.zeros(0, REAL)  # heading offset per entry: von Mises concentration and mean e^{i theta}
        self.mean = np.zeros(0, COMPLEX)
        self.ahead = np.zeros(groups)  # cells a group has moved ahead of its whole moves
        self.offmap = np.zeros(self.filters)
        self.evidence = np.zeros(self.filters)  # log-likelihood of the yaws seen since the start, per filter
        self.last_yaw = np.full(self.filters, np.nan)  # the odometry's yaw at the previous step, per filter
        self.running = np.zeros(self.filters, bool)
        self.split = np.zeros(self.filters, bool)
        # per filter and step: direction, yaw and the active cells by probability (None while there are many)
        self.history: list[list[Step]] = [[] for _ in range(self.filters)]
        self._dense = self.grid.num_cells // 8  # entries above which a group moves by one sparse matrix product
        # entries at or below which a filter splits into its scale classes: once the belief holds a few
        # percent of the map, where each split entry costs ``classes`` times as much
        self._split_at = min(self.grid.num_cells // 32, SPLIT_MAX)
        self._walks = model.settings.branches == "walks"
        self._distinct = DistinctKeys(self.filters * self.classes * self.grid.num_cells)  # (group, cell) keys
        self._owner_of, self._owner = self.group, self.group  # the entries' filters, for the ``group`` they came from
        self._summed_of: tuple[NDArray | None, ...] = (None, None, None)  # the entries :meth:`summed_belief` is of

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells

    # -- entries ---------------------------------------------------------------------------------------------

    @property
    def owner(self) -> NDArray[np.int64]:
        """The filter of each entry (``group // classes``), divided once per new ``group`` array (never changed
        in place)."""
        if self._owner_of is not self.group:
            self._owner_of, self._owner = self.group, self.group // self.classes
        return self._owner

    def summed_belief(self) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
        """The belief summed over the scale classes: each (filter, cell) it holds once, as (filter, cell, mass).

        Only a split filter holds a cell more than once (its entries are summed); the others' entries are their own
        sums. Computed once per set of entries (the places, the answers and the path's record of a step share it):
        the entries' arrays are only ever replaced, never changed in place."""
        if any(a is not b for a, b in zip(self._summed_of, (self.group, self.cell, self.weight))):
            owner = self.owner
            split = self.split[owner]
            if split.any():
                once = ~split
                filt, cell, mass = cell_sums(owner[split], self.cell[split], self.weight[split], self.num_cells,
                                             self._distinct)
                self._summed = (np.concatenate([owner[once], filt]), np.concatenate([self.cell[once], cell]),
                                np.concatenate([self.weight[once].astype(np.float64), mass]))
            else:
                self._summed = (owner, self.cell, self.weight.astype(np.float64))
            self._summed_of = (self.group, self.cell, self.weight)
        return self._summed

    def _set(self, group, cell, weight, kappa, mean) -> None:
        self.group, self.cell, self.weight, self.kappa, self.mean = group, cell, weight, kappa, mean

    def _keep(self, mask: NDArray[np.bool_]) -> tuple[NDArray, ...]:
        return tuple(a[mask] for a in (self.group, self.cell, self.weight, self.kappa, self.mean))

    def _counts(self, size: int = 1) -> NDArray[np.int64]:
        """Entries of every group (``size`` 1) or filter (``size`` = classes)."""
        return np.bincount(self.group if size == 1 else self.owner, minlength=self.filters * self.classes // size)

    def _filter_max(self, values: NDArray[np.floating]) -> NDArray[np.float64]:
        """Per filter, the largest of its entries' ``values`` (0 for a filter without entries)."""
        out = np.zeros(self.filters, values.dtype)
        np.maximum.at(out, self.owner, values)  # a per-filter max is exact in any order
        return out.astype(np.float64)

    def _merged(self, b: int, fresh: NDArray[np.float64] | None = None) -> tuple[NDArray, ...]:
        """Filter ``b``'s entries summed over its groups (plus ``fresh`` mass of unknown offset per cell), as
        entries of its nominal group."""
        mine = self.owner == b
        weight = np.zeros(self.num_cells, REAL) if fresh is None else fresh.astype(REAL)
        np.add.at(weight, self.cell[mine], self.weight[mine])
        resultant = np.zeros(self.num_cells, COMPLEX)  # mass of unknown offset dilutes the resultant
        np.add.at(resultant, self.cell[mine], self.weight[mine] * resultant_length(self.kappa[mine]) * self.mean[mine])
        cells = np.flatnonzero(weight > 0)
        length = np.abs(resultant[cells])
        mean = np.where(length > 0, resultant[cells] / np.maximum(length, TINY), 1.0)
        return (np.full(len(cells), b * self.classes + self.center), cells, weight[cells],
                concentration(length / weight[cells]), mean)

    # -- life cycle ------------------------------------------------------------------------------------------

    def start(self, which: int | NDArray[np.int64] | None = None) -> None:
        """(Re)start filters ``which`` (default: all): uniform over the map (by road length), offset unknown."""
        which = np.arange(self.filters) if which is None else np.atleast_1d(np.asarray(which, np.int64))
        keep = ~np.isin(self.owner, which)
        n = self.num_cells
        fresh = np.repeat(which * self.classes + self.center, n)
        self._set(np.concatenate([self.group[keep], fresh]), np.concatenate([self.cell[keep], np.tile(np.arange(n), len(which))]),
                  np.concatenate([self.weight[keep], np.tile(((1.0 - self.settings.offmap_prior) * self.grid.prior).astype(REAL),
                                                             len(which))]),
                  np.concatenate([self.kappa[keep], np.zeros(len(fresh), REAL)]),
                  np.concatenate([self.mean[keep], np.ones(len(fresh), COMPLEX)]))
        self.offmap[which] = self.settings.offmap_prior
        self.evidence[which] = 0.0
        self.last_yaw[which] = np.nan
        self.running[which] = True
        self.split[which] = False
        for b in which:
            self.ahead[b * self.classes:(b + 1) * self.classes] = 0.0
            self.history[int(b)] = []

    def stop(self, which: int | NDArray[np.int64]) -> None:
        """Stop filters ``which``: no entries, no steps (their history stays)."""
        which = np.atleast_1d(np.asarray(which, np.int64))
        self._set(*self._keep(~np.isin(self.owner, which)))
        self.running[which] = False

    def take(self, b: int) -> tuple[NDArray, ...]:
        """Filter ``b``'s belief summed over its scale classes: (cell, weight, kappa, mean); the filter stops."""
        _, cell, weight, kappa, mean = self._merged(b)
        self.stop(b)
        return cell, weight, kappa, mean

    def seed(self, b: int, cell: NDArray[np.int64], weight: NDArray, kappa: NDArray, mean: NDArray,
             offmap: float, last_yaw: float) -> None:
        """(Re)start filter ``b`` from a given belief (entries of its nominal scale class), not from the uniform one."""
        keep = self._keep(self.owner != b)
        fresh = (np.full(len(cell), b * self.classes + self.center), np.asarray(cell, np.int64), np.asarray(weight, REAL),
                 np.asarray(kappa, REAL), np.asarray(mean, COMPLEX))
        self._set(*(np.concatenate(p) for p in zip(keep, fresh)))
        self.offmap[b], self.last_yaw[b] = offmap, last_yaw
        self.running[b], self.split[b] = True, False
        self.ahead[b * self.classes:(b + 1) * self.classes] = 0.0

    def _reenter(self) -> None:
        """A lost filter (more likely off the map than on it) merges its groups and takes back ``enter_prob`` of
        its off-map mass, spread over the map; otherwise that mass would be negligible and is not spread."""
        lost = np.flatnonzero(self.running & (self.offmap >= 0.5) & (self.settings.enter_prob > 0))
        if len(lost) == 0:
            return
        parts = [self._keep(~np.isin(self.owner, lost))]
        for b in lost:
            fresh = self.offmap[b] * self.settings.enter_prob * self.grid.prior
            parts.append(self._merged(int(b), fresh))
            self.offmap[b] -= float(fresh.sum())
            self.split[b] = False
            self.ahead[b * self.classes:(b + 1) * self.classes] = 0.0
        self._set(*(np.concatenate(p) for p in zip(*parts)))

    def _split(self) -> None:
        """Filters whose belief is no longer broad split into their scale classes (prior share each)."""
        if self.classes == 1:
            return
        counts = self._counts(self.classes)
        ready = np.flatnonzero(self.running & ~self.split & (counts > 0) & (counts <= self._split_at))
        if len(ready) == 0:
            return
        mine = np.isin(self.owner, ready)
        parts = [self._keep(~mine)]
        group, cell, weight, kappa, mean = self._keep(mine)
        for k, share in enumerate(self.model.class_prior):
            # a double share makes the weights double from here on (the bank's entries share their arrays); single
            # weights would change near-tie answers in the last bits (docs/localization.md), so they stay so
            parts.append((group - self.center + k, cell, weight * share, kappa, mean))
        self._set(*(np.concatenate(p) for p in zip(*parts)))
        self.split[ready] = True
        for b in ready:
            self.ahead[b * self.classes:(b + 1) * self.classes] = 0.0

    # -- one step --------------------------------------------------------------------------------------------

    def _moves(self, yaw: float) -> NDArray[np.int64]:
        """Whole cells every group moves this step (one, or now and then none or two for a scale error or, in a
        turn, a lateral offset)."""
        filters = np.arange(self.filters * self.classes) // self.classes
        cells = np.where(self.split[filters], np.tile(self.step_cells, self.filters), 1.0)
        if self.offset_cells.any():
            turn = np.angle(np.exp(1j * (yaw - self.last_yaw)))  # NaN before a filter's first step
            turn = np.where(np.isfinite(turn), turn, 0.0)[filters]
            cells = cells - np.where(self.split[filters], np.tile(self.offset_cells, self.filters), 0.0) * turn
        total = self.ahead + cells
        moves = np.clip(np.floor(total + 0.5), 0, 2).astype(np.int64)  # nearest: a class is never half a cell behind
        self.ahead = np.clip(total - moves, -1.0, 1.0)
        return moves

    def _predict(self, direction: int, movers: NDArray[np.bool_]) -> None:
        """Move the entries of the groups ``movers`` (per group) one cell along the roads (back if ``direction`` < 0)."""
        model = self.model
        rows, cols = (model.forward, model.forward_cols) if direction > 0 else (model.backward, model.backward_cols)
        n = self.num_cells
        count = self._counts()
        dense = movers & (count > self._dense)
        moving = movers[self.group]
        everyone = bool(moving.all())
        entries = (self.group, self.cell, self.weight, self.kappa, self.mean)
        group, cell, weight, kappa, mean = entries if everyone else (a[moving] for a in entries)  # the movers'
        carried = weight * resultant_length(kappa) * mean
        moved: dict[int, tuple] = {}
        for g in np.flatnonzero(dense):  # a broad belief: one sparse matrix product
            mine = group == g
            at, flow = cell[mine], carried[mine]
            flows = []
            for part in (weight[mine], flow.real, flow.imag):
                full = np.zeros(n, REAL)
                full[at] = part
                flows.append(cols @ full)
            cells = np.flatnonzero(flows[0] > 0)
            moved[int(g)] = (cells, flows[0][cells], (flows[1][cells] + 1j * flows[2][cells]).astype(COMPLEX))
        sparse = ~dense[group]
        if sparse.any():  # concentrated beliefs, all groups together: the moves of their cells
            owner, dst, p = gather_rows(rows, cell[sparse])
            keys, inverse = self._distinct(group[sparse][owner] * n + dst)
            flow = carried[sparse][owner] * p
            sums = np.bincount(inverse, weights=weight[sparse][owner] * p, minlength=len(keys)).astype(REAL)
            resultant = (np.bincount(inverse, weights=flow.real, minlength=len(keys))
                         + 1j * np.bincount(inverse, weights=flow.imag, minlength=len(keys))).astype(COMPLEX)
            moved[-1] = (keys, sums, resultant)  # as keys group * n + cell
        if not moved:
            return
        group = np.concatenate([np.full(len(c), g) if g >= 0 else c // n for g, (c, _, _) in moved.items()])
        cell = np.concatenate([c if g >= 0 else c % n for g, (c, _, _) in moved.items()])
        weight, resultant = (np.concatenate([part[i] for part in moved.values()]) for i in (1, 2))
        length = np.abs(resultant)
        kappa = concentration(length / np.maximum(weight, TINY))
        kappa = kappa / (1.0 + kappa * model.drift[cell])  # the offset diffuses: variance 1 / kappa + drift
        mean = np.where(length > 0, resultant / np.maximum(length, TINY), 1.0)
        if everyone:  # no copy, the dtypes a concatenation would give
            self._set(*(b.astype(np.result_type(a, b), copy=False) for a, b in zip(entries, (group, cell, weight, kappa, mean))))
            return
        self._set(*(np.concatenate([a[~moving], b]) for a, b in zip(entries, (group, cell, weight, kappa, mean))))

    def update(self, direction: int, yaw: float) -> None:
        """One step of ``cell_m`` forward (``direction`` > 0) or back, with the odometry's ``yaw`` (radians),
        for every running filter."""
        model = self.model
        self._reenter()
        moves = self._moves(yaw)
        before = np.bincount(self.owner, weights=self.weight, minlength=self.filters) if self._walks else None
        for move in (1, 2):
            if (moves >= move).any():
                self._predict(direction, moves >= move)
        if before is not None:  # every way on from a node kept the whole probability: keep each filter's total
            filt = self.owner
            after = np.bincount(filt, weights=self.weight, minlength=self.filters)
            self.weight = self.weight * (before / np.maximum(after, TINY))[filt].astype(REAL)
        leave = self.settings.leave_prob
        filt = self.owner
        self.offmap += leave * np.bincount(filt, weights=self.weight, minlength=self.filters)  # float64 per filter
        kappa, kappa_obs, mean = self.kappa, model.kappa_obs[self.cell], self.mean
        sample = complex(math.cos(yaw), math.sin(yaw)) * model.unheading[self.cell]  # e^{i (yaw - h)}: an offset sample
        cos_delta = (sample * mean.conj()).real
        kappa_eff = kappa * kappa_obs / (kappa + kappa_obs)  # the predicted offset and the observation, convolved
        norm = kappa_eff if model.norm_kappa is None else kappa * model.norm_kappa / (kappa + model.norm_kappa)
        inlier = ((1.0 - self.settings.floor) * np.exp(kappa_eff * (cos_delta - 1.0))
                  * np.sqrt(norm / TWO_PI + 1.0 / TWO_PI**2))  # von Mises density, normaliser approximated
        like = inlier + model.floor_density
        natural = kappa * mean + (inlier / like) * kappa_obs * sample  # the inlier share of the observation
        self.kappa = np.abs(natural)
        self.mean = natural / np.maximum(self.kappa, TINY)
        off_like = model.offmap_density(yaw - self.last_yaw)
        self.last_yaw = np.where(self.running, yaw, self.last_yaw)
        weight = self.weight * ((1.0 - leave) * like)
        offmap = self.offmap * off_like
        on_map = np.bincount(filt, weights=weight, minlength=self.filters)
        total = on_map + offmap
        total = np.where(total > 0, total, 1.0)
        self.evidence += np.where(self.running, np.log(total), 0.0)
        self.weight = weight / total[filt].astype(REAL)
        self.offmap = offmap / total
        keep = self.weight >= (self.prune * self._filter_max(self.weight))[filt].astype(REAL)
        if not keep.all():
            self._set(*self._keep(keep))
        self._split()
        self._remember(direction, yaw)

    def _remember(self, direction: int, yaw: float) -> None:
        """Each running filter's active cells of this step, most probable first (for :meth:`path`); when there
        are more than ``keep_top``, none (the trace then follows the motion and the heading)."""
        few = self._counts(self.classes) <= self.keep_top * self.classes
        running = np.flatnonzero(self.running)
        for b, cells in zip(running.tolist(), ranked_cells(*self.summed_belief(), running, few, self.keep_top)):
            self.history[b].append((int(direction), float(yaw), cells))

    # -- answers ---------------------------------------------------------------------------------------------

    def edge_marginals(self) -> NDArray[np.float64]:
        """Probability of each undirected road, per filter: ``(filters, roads)``."""
        roads = self.grid.num_roads
        filt, cell, mass = self.summed_belief()
        flat = np.bincount(filt * roads + self.grid.edge[cell], weights=mass, minlength=self.filters * roads)
        return flat.reshape(self.filters, roads)

    def roads(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Per filter, the road of largest probability and that probability (:meth:`answers` without the cells)."""
        marginal = self.edge_marginals()
        edge = np.argmax(marginal, axis=1)
        return edge, marginal[np.arange(self.filters), edge]

    def answers(self) -> list[Estimate]:
        """Per filter: the road of largest probability, its cell of most mass (the scale classes' entries of a cell
        added up, as :meth:`places` adds them), and that probability."""
        edge, confidence = self.roads()
        roads = self.grid.num_roads
        filt, cell, mass = self.summed_belief()
        on = self.grid.edge[cell] == edge[filt]
        most, best = cells_of_most_mass(filt[on], cell[on], mass[on], self.grid.edge, self.filters, roads)
        key = np.arange(self.filters) * roads + edge
        out = []
        for b in range(self.filters):
            if most[key[b]] < 0:  # no entries on its road: none at all
                out.append(Estimate(-1, -1, np.full(2, np.nan), 0.0, float(self.offmap[b])))
                continue
            cell = int(best[key[b]])
            out.append(Estimate(int(edge[b]), cell, self.grid.xy[cell].copy(), float(confidence[b]), float(self.offmap[b])))
        return out

    def answer(self, which: int = 0) -> Estimate:
        """The answer of filter ``which``."""
        return self.answers()[which]

    def places(self, k: int, merge_m: float = 0.0, which: NDArray[np.int64] | None = None,
               shift_m: float = 0.0) -> list[list[Place]]:
        """Per filter (or per filter in ``which``), its ``k`` most probable places
        (:func:`topoloc.localization.places.belief_places`), each ``shift_m`` metres on along its cell's heading
        (the distance driven since the last step)."""
        filt, cell, mass = self.summed_belief()
        return belief_places(filt, cell, mass, self.grid.edge, self.grid.xy, self.filters, self.grid.num_roads, k,
                             merge_m, which, shift_m, self.model.direction, summed=True)

    def top_places(self, k: int, merge_m: float = 0.0, which: int = 0, shift_m: float = 0.0) -> list[Place]:
        """The ``k`` most probable places of filter ``which`` (:class:`topoloc.localizer.RankedFilter`)."""
        return self.places(k, merge_m, shift_m=shift_m)[which]

    def path(self, which: int = 0) -> NDArray[np.int64]:
        """A consistent cell sequence of filter ``which``, traced back from its last step's most probable cell
        (:func:`topoloc.localization.metric.trace.trace_back`, with that cell's heading offset)."""
        history = self.history[which]
        if not history or history[-1][2] is None or not len(history[-1][2]):
            return np.full(len(history), -1, np.int64)
        on = (self.owner == which) & (self.cell == history[-1][2][0])
        offset = complex(self.mean[on][np.argmax(self.weight[on])]) if on.any() else 1.0 + 0.0j
        return trace_back(self.model, history, offset)
