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

:meth:`CellHMM.decode` runs the forward filter (``online``: the edge with
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

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class HmmParams:
    """Parameters of the baseline (config ``localization.hmm``)."""

    cell_m: float = 5.0
    angle_sigma_deg: float = 20.0
    distance_sigma_m: float = 2.5
    straight_virtual_prob: float = 0.85
    floor: float = 0.01
    reset_prob: float = 1e-4
    heading_window_m: float = 10.0

    @classmethod
    def from_conf(cls, conf: dict[str, Any] | None) -> HmmParams:
        return cls(**{k: float(v) for k, v in (conf or {}).items() if k in cls.__dataclass_fields__})


def _headings(coords: NDArray, positions: NDArray, half: float) -> NDArray[np.float64]:
    """Travel heading (degrees, counter-clockwise from +x) of a polyline at ``positions`` over +-``half`` metres."""
    seg = np.hypot(*np.diff(coords, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    a = np.clip(positions - half, 0.0, cum[-1])
    b = np.clip(positions + half, 0.0, cum[-1])
    b = np.where(b - a < 1e-6, np.minimum(a + 1e-3, cum[-1]), b)
    a = np.where(b - a < 1e-6, np.maximum(b - 1e-3, 0.0), a)
    dx = np.interp(b, cum, coords[:, 0]) - np.interp(a, cum, coords[:, 0])
    dy = np.interp(b, cum, coords[:, 1]) - np.interp(a, cum, coords[:, 1])
    return np.degrees(np.arctan2(dy, dx))


class CellHMM:
    """The baseline on one road graph; build once, :meth:`decode` many token sequences."""

    def __init__(self, graph: RoadGraph, states: DirectedEdges, bins: int, params: HmmParams = HmmParams()) -> None:
        self.states, self.bins, self.params = states, bins, params
        self.spacing = graph.virtual_node_spacing_m
        valid = np.flatnonzero(states.valid)
        counts = np.zeros(states.num_states, np.int64)
        counts[valid] = np.maximum(1, np.ceil(states.length[valid] / params.cell_m - 1e-9)).astype(np.int64)
        self.cell_len = np.where(counts > 0, states.length / np.maximum(counts, 1), 0.0)
        self.base = np.concatenate([[0], np.cumsum(counts)])
        self.cell_state = np.repeat(np.arange(states.num_states), counts)
        self.cell_index = np.arange(len(self.cell_state)) - self.base[self.cell_state]
        self.cell_pos = (self.cell_index + 0.5) * self.cell_len[self.cell_state]
        self.cell_edge = states.edge[self.cell_state]
        heading = np.empty(len(self.cell_state))
        for s in valid:
            coords = graph.geometry[s // 2] if s % 2 == 0 else graph.geometry[s // 2][::-1]
            cells = slice(self.base[s], self.base[s + 1])
            heading[cells] = _headings(np.asarray(coords, float), self.cell_pos[cells], params.heading_window_m / 2.0)
        self.cell_heading = heading
        self._build_moves()

    @property
    def num_cells(self) -> int:
        return len(self.cell_state)

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
        st = self.states
        dists, p_dist = self._distances()
        src_l, dst_l, opt_l, w_l = [], [], [], []
        for opt, dist in enumerate(dists):
            src = np.arange(self.num_cells)
            s = self.cell_state.copy()
            q = self.cell_pos + dist
            w = np.ones(self.num_cells)
            for _ in range(64):  # hops across nodes; stops when every move has landed
                inside = q < st.length[s]
                if inside.any():
                    self._land(src[inside], s[inside], q[inside], w[inside], opt, src_l, dst_l, opt_l, w_l)
                out = ~inside
                if not out.any():
                    break
                src, s, q, w = src[out], s[out], q[out] - st.length[s[out]], w[out]
                counts = st.next_ptr[s + 1] - st.next_ptr[s]
                rep = np.repeat(np.arange(len(s)), counts)
                offset = np.arange(len(rep)) - np.repeat(np.cumsum(counts) - counts, counts)
                nxt = st.next_idx[st.next_ptr[s][rep] + offset]
                src, q, w, s = src[rep], q[rep], w[rep] / counts[rep], nxt
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

    def _land(self, src, s, q, w, opt, src_l, dst_l, opt_l, w_l) -> None:
        """Split each landing position between the two nearest cell centres of its state."""
        n = self.base[s + 1] - self.base[s]
        x = q / self.cell_len[s] - 0.5
        lo = np.clip(np.floor(x), 0, n - 1).astype(np.int64)
        frac = np.clip(x - lo, 0.0, 1.0)
        hi = np.minimum(lo + 1, n - 1)
        frac = np.where(hi == lo, 0.0, frac)
        for cell, share in ((lo, 1.0 - frac), (hi, frac)):
            keep = share > 0
            src_l.append(src[keep])
            dst_l.append(self.base[s[keep]] + cell[keep])
            opt_l.append(np.full(int(keep.sum()), opt))
            w_l.append(w[keep] * share[keep])

    def _edge_marginal(self, alpha: NDArray) -> NDArray[np.float64]:
        return np.bincount(self.cell_edge, weights=alpha, minlength=self.states.num_edges)

    def decode(self, tokens: NDArray[np.int64], initial_k: int = 5) -> Decoded:
        """Forward filter (online) and Viterbi path (consistent) of one drive's tokens."""
        tokens = np.asarray(tokens, np.int64)
        if len(tokens) == 0:
            raise ValueError("no tokens")
        n = self.num_cells
        reset = self.params.reset_prob
        log_reset = math.log(reset / n) if reset > 0 else -np.inf
        alpha = np.full(n, 1.0 / n)
        delta = np.full(n, -math.log(n))
        online, confidence = np.empty(len(tokens), np.int64), np.empty(len(tokens))
        back = np.empty((len(tokens), n), np.int32)
        log_evidence, restarts = 0.0, 0
        initial = np.zeros(0, np.int64)
        for t, token in enumerate(tokens):
            new = np.bincount(self.dst, weights=alpha[self.src] * self.weights[token], minlength=n)
            total = new.sum()
            log_evidence += math.log(max(total, 1e-300))
            alpha = new / total if total > 0 else np.full(n, 1.0 / n)
            if reset > 0:
                alpha = (1 - reset) * alpha + reset / n
            marginal = self._edge_marginal(alpha)
            online[t] = int(np.argmax(marginal))
            confidence[t] = float(marginal[online[t]])
            if t == 0:
                initial = np.argsort(-marginal, kind="stable")[:initial_k]
            # Viterbi: the best way into each cell (entries are grouped by destination)
            score = delta[self.src] + self.log_weights[token]
            best = np.full(n, -np.inf)
            best[self.dst_cells] = np.maximum.reduceat(score, self.dst_start)
            hit = score >= np.repeat(best[self.dst_cells], np.diff(np.append(self.dst_start, len(score))))
            arg = np.maximum.reduceat(np.where(hit, np.arange(len(score)), -1), self.dst_start)
            pointer = np.full(n, -1, np.int64)
            pointer[self.dst_cells] = self.src[arg]
            top = int(np.argmax(delta))
            pointer = np.where(pointer < 0, top, pointer)
            if reset > 0:  # a fresh start from the best cell beats the best way in
                take = delta[top] + log_reset > best
                best = np.where(take, delta[top] + log_reset, best)
                pointer = np.where(take, -1 - top, pointer)
            delta = best - best.max()
            back[t] = pointer
        path_cells = np.empty(len(tokens), np.int64)
        cell = int(np.argmax(delta))
        for t in range(len(tokens) - 1, -1, -1):
            path_cells[t] = cell
            cell = int(back[t, cell])
            if cell < 0:
                restarts += t > 0
                cell = -1 - cell
        path = self.cell_edge[path_cells]
        extra = {"log_evidence": log_evidence, "explained_turns": self.explained_turns(tokens, path_cells),
                 "turn_tokens": int(np.sum(tokens[1:] != straight_token(self.bins)))}
        return Decoded(online, path, confidence, initial, restarts, np.full(len(tokens), n, np.int64), extra=extra)

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
