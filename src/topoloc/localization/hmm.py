"""A classical baseline without learning: an HMM over positions on directed edges, from the same tokens.

In the spirit of map-based probabilistic localization from odometry
(Brubaker, Geiger and Urtasun, "Lost! Leveraging the crowd for probabilistic
visual self-localization", CVPR 2013), reduced to the token input of the RNN:

* **States**: every directed edge (a road in an allowed direction) is cut
  into cells of at most ``cell_m`` metres; a state is a cell. The start is
  unknown: the prior is uniform over cells (so over road length).
* **Motion**: each token moves the vehicle forward by a distance ``D`` along
  the road network; at a node it takes any road that may follow
  (:mod:`topoloc.localization.connectivity`), each with equal probability. A
  straight token is most likely a virtual node, one spacing after the last
  token (``D`` ~ spacing, standard deviation ``distance_sigma_m``), else a
  straight corner; a turn token is a corner, reached within one spacing
  (``D`` uniform on (0, spacing]). Landing between two cell centres splits
  the probability between them (linear interpolation).
* **Observation**: the token's turning angle against the map's: the turning
  angle (:mod:`topoloc.geometry` convention) from the road heading at the
  old cell to the road heading at the new one, with Gaussian noise of
  ``angle_sigma_deg`` (wrapped), normalised over the ``bins`` tokens and
  mixed with a uniform ``floor``.
* **Robustness**: ``reset_prob`` of the mass is spread uniformly at every step
  (a lost vehicle can be found again).

:meth:`CellHMM.run` runs the forward filter (``online``: the edge with
the largest marginal after each step; ``confidence``: that marginal) and the
Viterbi path (``path``), vectorised over cells with ``np.bincount`` /
``np.maximum.reduceat`` on a fixed sparse transition structure.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.encoding import turning_angle_from_headings
from topoloc.geometry import bin_centre, straight_token
from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.connectivity import DirectedEdges
from topoloc.localization.decoders import Decoded
from topoloc.localization.metric.cell_grid import CellGrid, Chains
from topoloc.localization.places import belief_places
from topoloc.localizer import Place

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class HmmParams:
    """Parameters of the baseline (config ``localization.hmm``)."""

    cell_m: float
    angle_sigma_deg: float
    distance_sigma_m: float
    straight_virtual_prob: float
    floor: float
    reset_prob: float
    heading_window_m: float

    @classmethod
    def from_conf(cls, conf: dict[str, Any]) -> HmmParams:
        """The parameters of the validated config slice ``localization.hmm``."""
        return cls(**{k: float(conf[k]) for k in cls.__dataclass_fields__})


class CellHMM:
    """The baseline on one road graph; build once, then :meth:`run` a token sequence, or :meth:`start`,
    :meth:`update` one token at a time and :meth:`path` the Viterbi path (:class:`topoloc.localizer.Filter`)."""

    def __init__(self, graph: RoadGraph, states: DirectedEdges, bins: int, params: HmmParams,
                 lane_offset_m: NDArray[np.float64] | None = None) -> None:
        self.states, self.bins, self.params = states, bins, params
        self.spacing = graph.virtual_node_spacing_m
        self.grid = CellGrid(graph, states, Chains.of_states(states), params.cell_m, params.heading_window_m,
                             lane_offset_m)
        self.cell_edge, self.cell_heading = self.grid.edge, self.grid.heading
        self._owner, self._cells = np.zeros(self.num_cells, np.int64), np.arange(self.num_cells)  # for top_places
        self._build_moves()

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells

    def _distances(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Step lengths ``D`` and their probabilities for (straight, turn) tokens: shape ``(2, len(D))``."""
        n = max(1, round(self.spacing / self.params.cell_m))
        step = self.spacing / n
        d = step * np.arange(1, n + 3)  # up to two cells past one spacing
        near = np.exp(-0.5 * ((d - self.spacing) / max(self.params.distance_sigma_m, 1e-6)) ** 2)
        within = (d <= self.spacing + 1e-9).astype(float)
        p_v = self.params.straight_virtual_prob
        straight = p_v * near / near.sum() + (1 - p_v) * within / within.sum()
        return d, np.stack([straight, within / within.sum()])

    def _build_moves(self) -> None:
        dists, p_dist = self._distances()
        src_l, dst_l, opt_l, w_l = [], [], [], []
        for opt, dist in enumerate(dists):
            moves = self.grid.moves(dist)
            src_l.append(moves.src)
            dst_l.append(moves.dst)
            opt_l.append(np.full(len(moves.src), opt))
            w_l.append(moves.weight)
        src, dst = np.concatenate(src_l), np.concatenate(dst_l)
        opt, w = np.concatenate(opt_l), np.concatenate(w_l)
        order = np.lexsort((src, dst))
        self.src, self.dst, opt, w = src[order], dst[order], opt[order], w[order]
        self.dst_cells, self.dst_start = np.unique(self.dst, return_index=True)
        phi = turning_angle_from_headings(self.cell_heading[self.src], self.cell_heading[self.dst])
        centres = np.asarray(bin_centre(np.arange(self.bins), self.bins))
        diff = np.mod(centres[:, None] - phi[None, :] + 180.0, 360.0) - 180.0
        like = np.exp(-0.5 * (diff / self.params.angle_sigma_deg) ** 2)
        like = (1 - self.params.floor) * like / like.sum(axis=0, keepdims=True) + self.params.floor / self.bins
        kind = np.where(np.arange(self.bins) == straight_token(self.bins), 0, 1)
        self.weights = (like * p_dist[kind][:, opt] * w[None, :]).astype(np.float32)  # (bins, entries)
        with np.errstate(divide="ignore"):
            self.log_weights = np.log(self.weights)
        log.info("HMM: %d cells, %d transitions", self.num_cells, len(self.src))

    def _edge_marginal(self, alpha: NDArray) -> NDArray[np.float64]:
        return np.bincount(self.cell_edge, weights=alpha, minlength=self.states.num_edges)

    def start(self) -> None:
        """The prior: uniform over cells (so over road length)."""
        n = self.num_cells
        self.alpha = np.full(n, 1.0 / n)
        self.delta = np.full(n, -math.log(n))
        self.back: list[NDArray[np.int32]] = []
        self.log_evidence = 0.0
        self.initial = np.zeros(0, np.int64)
        self.online: tuple[int, float] = (-1, 0.0)

    def forward(self, alpha: NDArray, token: int, evidence: NDArray[np.float64] | None = None) -> tuple[NDArray, float]:
        """One forward step of the belief ``alpha`` for ``token`` (with the per-cell log-likelihood ``evidence``, if
        any), without touching the filter's own state: the new belief and the total mass before normalising."""
        n = self.num_cells
        new = np.bincount(self.dst, weights=alpha[self.src] * self.weights[token], minlength=n)
        if evidence is not None:
            new = new * np.exp(evidence - evidence.max())
        total = float(new.sum())
        out = new / total if total > 0 else np.full(n, 1.0 / n)
        reset = self.params.reset_prob
        return ((1 - reset) * out + reset / n if reset > 0 else out), total

    def update(self, token: int, initial_k: int = 5, evidence: NDArray[np.float64] | None = None) -> tuple[int, float]:
        """Forward filter and Viterbi step for one token; the online answer (edge, its marginal).

        ``evidence``: an extra log-likelihood per cell of this step (e.g. a learned model's, see
        :mod:`topoloc.localizers.rnn_filter`), multiplied into the forward and Viterbi scores.
        """
        n = self.num_cells
        reset = self.params.reset_prob
        alpha, total = self.forward(self.alpha, token, evidence)
        self.log_evidence += math.log(max(total, 1e-300))
        self.alpha = alpha
        marginal = self._edge_marginal(alpha)
        online = int(np.argmax(marginal))
        if not self.back:
            self.initial = np.argsort(-marginal, kind="stable")[:initial_k]
        # Viterbi: the best way into each cell (entries are grouped by destination)
        delta = self.delta
        score = delta[self.src] + self.log_weights[token]
        if evidence is not None:
            score = score + evidence[self.dst]
        best = np.full(n, -np.inf)
        best[self.dst_cells] = np.maximum.reduceat(score, self.dst_start)
        hit = score >= np.repeat(best[self.dst_cells], np.diff(np.append(self.dst_start, len(score))))
        arg = np.maximum.reduceat(np.where(hit, np.arange(len(score)), -1), self.dst_start)
        pointer = np.full(n, -1, np.int64)
        pointer[self.dst_cells] = self.src[arg]
        top = int(np.argmax(delta))
        pointer = np.where(pointer < 0, top, pointer)
        if reset > 0:  # a fresh start from the best cell beats the best way in
            take = delta[top] + math.log(reset / n) > best
            best = np.where(take, delta[top] + math.log(reset / n), best)
            pointer = np.where(take, -1 - top, pointer)
        self.delta = best - best.max()
        self.back.append(pointer.astype(np.int32))
        self.online = (online, float(marginal[online]))
        return self.online

    def answer(self) -> tuple[int, float]:
        """The online answer after the last token (edge, its marginal); (-1, 0) before the first."""
        return self.online

    def top_places(self, k: int, merge_m: float = 0.0, alpha: NDArray | None = None) -> list[Place]:
        """The ``k`` most probable places of the forward belief, or of belief ``alpha``
        (:class:`topoloc.localizer.RankedFilter`)."""
        return belief_places(self._owner, self._cells, self.alpha if alpha is None else alpha, self.cell_edge,
                             self.grid.xy, 1, self.states.num_edges, k, merge_m, summed=True)[0]  # each cell once

    def path(self) -> tuple[NDArray[np.int64], int]:
        """The Viterbi cells of the steps so far, and the number of fresh starts on it."""
        steps = len(self.back)
        path_cells = np.empty(steps, np.int64)
        restarts = 0
        cell = int(np.argmax(self.delta))
        for t in range(steps - 1, -1, -1):
            path_cells[t] = cell
            cell = int(self.back[t][cell])
            if cell < 0:
                restarts += t > 0
                cell = -1 - cell
        return path_cells, restarts

    def run(self, tokens: NDArray[np.int64], initial_k: int = 5) -> Decoded:
        """The batch form: forward filter (online) and Viterbi path (consistent) of one drive's tokens."""
        tokens = np.asarray(tokens, np.int64)
        if len(tokens) == 0:
            raise ValueError("no tokens")
        self.start()
        answers = [self.update(int(token), initial_k) for token in tokens]
        path_cells, restarts = self.path()
        online = np.array([a for a, _ in answers], np.int64)
        confidence = np.array([c for _, c in answers], float)
        extra = {"log_evidence": self.log_evidence, "explained_turns": self.explained_turns(tokens, path_cells),
                 "turn_tokens": int(np.sum(tokens[1:] != straight_token(self.bins)))}
        return Decoded(online, self.cell_edge[path_cells], confidence, self.initial, restarts,
                       np.full(len(tokens), self.num_cells, np.int64), extra=extra)

    def explained_turns(self, tokens: NDArray[np.int64], path_cells: NDArray[np.int64]) -> float:
        """Share of the turn tokens (not straight) that the map's turn along the Viterbi path matches within ``angle_sigma_deg``.

        On the map a drive was made on, most turns match; a drive from elsewhere has to be bent onto
        roads that do not turn where it does (see ``localization.min_explained_turns``).
        """
        turns = np.flatnonzero(np.asarray(tokens)[1:] != straight_token(self.bins)) + 1
        if len(turns) == 0:
            return float("nan")
        phi = turning_angle_from_headings(self.cell_heading[path_cells[turns - 1]], self.cell_heading[path_cells[turns]])
        diff = np.abs(np.mod(np.asarray(bin_centre(tokens[turns], self.bins)) - phi + 180.0, 360.0) - 180.0)
        return float(np.mean(diff <= self.params.angle_sigma_deg))
