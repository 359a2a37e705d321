"""Decoding the RNN's per-step edge probabilities into localization hypotheses (the paper's Sec. III-B).

All decoders take ``logp``, the ``(T, E)`` log-probabilities of the RNN over the
(undirected) edge ids at each token, and return a :class:`Decoded`:

* :func:`decode_raw`: the argmax edge at each step (no consistency).
* :func:`decode_strategy1`: hypotheses on all edges at ``t = 0`` (or the top
  ``k``); each hypothesis expands to the states that can follow it
  (:mod:`topoloc.localization.connectivity`), scored by Eq. 5 accumulated
  along the hypothesis, and the top ``k`` are kept.
* :func:`decode_strategy2`: the top ``k`` edges of the RNN at each step, less
  those that cannot follow a surviving hypothesis. When none can, the truth
  was outside the top ``k`` (the paper's warning) and the decoder restarts
  from the top ``k`` of that step: the decoded sequence breaks there.

Scores (``score``): ``joint`` adds ``log P_t(e)`` of the new edge, i.e. Eq. 5's
numerator ``P(H_t^ij, H_{t-1}^i)`` with the RNN's step outputs taken as
independent, so hypotheses over the same steps compare by their joint
probability; ``conditional`` is Eq. 5 read literally, ``P_t(e)`` renormalized
over the edges the hypothesis can move to. Both track (edge, direction)
states; outputs are undirected edge ids.

Long drives: a hypothesis that left the beam never returns, so ``reseed``
optionally injects the RNN's top ``reseed`` edges at every step as fresh
hypotheses, scored ``reseed_penalty`` nats below the best one (they win only
when the old hypotheses keep scoring worse; each win is a break in the
decoded sequence, counted in ``restarts``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from topoloc.localization.connectivity import DirectedEdges

STRATEGIES = ("strategy1", "strategy2")
SCORES = ("joint", "conditional")


@dataclass
class Decoded:
    """A decoder's answer for one drive (edge ids are undirected)."""

    online: NDArray[np.int64]  #: (T,) edge of the best hypothesis after each step (what a user sees live)
    path: NDArray[np.int64]  #: (T,) the best final hypothesis traced back (the consistent edge sequence)
    confidence: NDArray[np.float64]  #: (T,) probability share of the online edge among the hypotheses
    initial: NDArray[np.int64]  #: the top initial hypotheses (edges), best first (Fig. 9c)
    restarts: int = 0  #: breaks: strategy 2 restarts and re-seeded hypotheses that took over
    hypotheses: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))  #: (T,) alive per step
    extra: dict = field(default_factory=dict)


def log_softmax(logits: NDArray) -> NDArray[np.float64]:
    """Row-wise log-softmax of ``(T, E)`` logits."""
    x = np.asarray(logits, dtype=np.float64)
    x = x - x.max(axis=-1, keepdims=True)
    return x - np.log(np.exp(x).sum(axis=-1, keepdims=True))


def _top_edges(row: NDArray, k: int) -> NDArray[np.int64]:
    k = min(k, len(row))
    top = np.argpartition(-row, k - 1)[:k]
    return top[np.argsort(-row[top], kind="stable")]


def decode_raw(logp: NDArray, initial_k: int = 5) -> Decoded:
    """The argmax edge at each step."""
    logp = np.asarray(logp)
    arg = logp.argmax(axis=1).astype(np.int64)
    conf = np.exp(logp[np.arange(len(arg)), arg])
    return Decoded(arg, arg.copy(), conf, _top_edges(logp[0], initial_k) if len(logp) else arg[:0],
                   hypotheses=np.ones(len(arg), np.int64))


def _share(scores: NDArray, edges: NDArray, best_edge: int) -> float:
    p = np.exp(scores - scores.max())
    return float(p[edges == best_edge].sum() / p.sum())


class Beam:
    """Multi-hypothesis decoding one step at a time (see the module docstring), with the methods of
    :class:`topoloc.localizer.Filter`: :meth:`start`, :meth:`update`, :meth:`answer`, :meth:`path`."""

    def __init__(self, states: DirectedEdges, strategy: str = "strategy1", k: int = 5, initial: str = "all",
                 score: str = "joint", reseed: int = 0, reseed_penalty: float = 5.0, initial_k: int = 5) -> None:
        if strategy not in STRATEGIES:
            raise ValueError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
        if score not in SCORES:
            raise ValueError(f"score must be one of {SCORES}, got {score!r}")
        if initial not in ("all", "top_k"):
            raise ValueError(f"initial must be 'all' or 'top_k', got {initial!r}")
        self.states, self.strategy, self.k, self.initial, self.score = states, strategy, k, initial, score
        self.reseed, self.reseed_penalty, self.initial_k = reseed, reseed_penalty, initial_k
        self.valid_states = np.flatnonzero(states.valid)
        self.start()

    def start(self) -> None:
        """Forget every step: no hypotheses (the first :meth:`update` seeds them)."""
        self.hist_state: list[NDArray[np.int64]] = []

    def update(self, logp: NDArray) -> tuple[int, float]:
        """Take the next step's ``logp``; the online answer (edge, confidence)."""
        return self._expand(logp) if self.hist_state else self._seed(logp)

    def answer(self) -> tuple[int, float]:
        """The online answer after the last step (edge, confidence); (-1, 0) before the first."""
        return self._online() if self.hist_state else (-1, 0.0)

    def _seed(self, logp: NDArray) -> tuple[int, float]:
        """Hypotheses on every valid state (or on the top ``k`` edges) from the first step's ``logp``; online answer."""
        logp = np.asarray(logp, dtype=np.float64)
        edge_of, k = self.states.edge, self.k
        top_only = self.strategy == "strategy2" or self.initial == "top_k"
        beam = self.states.states_of(_top_edges(logp, k)) if top_only else self.valid_states
        scores = logp[edge_of][beam]
        order = np.argsort(-scores, kind="stable")
        beam, scores = beam[order], scores[order]
        if top_only:
            beam, scores = beam[:k], scores[:k]
        self.beam, self.scores = beam, scores
        self.hist_state = [beam]
        self.hist_parent = [np.full(len(beam), -1, np.int64)]
        self.initial_edges = np.asarray(list(dict.fromkeys(edge_of[beam[:max(k, self.initial_k) * 2]].tolist()))[:self.initial_k],
                                        np.int64)
        self.restarts = 0
        return self._online()

    def _online(self) -> tuple[int, float]:
        best = int(self.states.edge[self.beam[0]])
        return best, _share(self.scores, self.states.edge[self.beam], best)

    def _expand(self, logp: NDArray) -> tuple[int, float]:
        """Expand the hypotheses with the next step's ``logp``; the online answer (edge, confidence)."""
        logp = np.asarray(logp, dtype=np.float64)
        states, k, edge_of = self.states, self.k, self.states.edge
        succ, width = states.successors, states.successors.shape[1]
        beam, scores = self.beam, self.scores
        lp = logp[edge_of]
        cand = succ[beam].reshape(-1)
        parent = np.repeat(np.arange(len(beam)), width)
        keep = cand >= 0
        cand, parent = cand[keep], parent[keep]
        cand_scores = scores[parent] + lp[cand]
        if self.score == "conditional":
            rows = succ[beam]
            row_lp = np.where(rows >= 0, lp[np.maximum(rows, 0)], -np.inf)
            cand_scores = cand_scores - np.logaddexp.reduce(row_lp, axis=1)[parent]
        fresh = np.zeros(len(cand), dtype=bool)
        if self.strategy == "strategy2":
            allowed = np.zeros(states.num_states, dtype=bool)
            allowed[states.states_of(_top_edges(logp, k))] = True
            ok = allowed[cand]
            cand, parent, cand_scores, fresh = cand[ok], parent[ok], cand_scores[ok], fresh[ok]
            if len(cand) == 0:  # the truth was outside the top k: start over from this step's top k
                self.restarts += 1
                cand = np.flatnonzero(allowed)
                parent = np.zeros(len(cand), np.int64)
                cand_scores = scores[0] + lp[cand]
                fresh = np.ones(len(cand), dtype=bool)
        if self.reseed > 0:
            seeds = states.states_of(_top_edges(logp, self.reseed))
            cand = np.concatenate([cand, seeds])
            parent = np.concatenate([parent, np.zeros(len(seeds), np.int64)])
            cand_scores = np.concatenate([cand_scores, scores[0] - self.reseed_penalty + lp[seeds]])
            fresh = np.concatenate([fresh, np.ones(len(seeds), dtype=bool)])
        order = np.argsort(-cand_scores, kind="stable")
        cand, parent, cand_scores, fresh = cand[order], parent[order], cand_scores[order], fresh[order]
        _, first = np.unique(cand, return_index=True)  # recombine: the best way into each state
        first = np.sort(first)[:k]
        if self.reseed > 0 and fresh[first[0]] and self.strategy == "strategy1":
            self.restarts += 1
        self.beam, self.scores = cand[first], cand_scores[first] - cand_scores[first[0]]
        self.hist_state.append(self.beam)
        self.hist_parent.append(np.where(fresh[first], -2, parent[first]))
        return self._online()

    @property
    def alive(self) -> int:
        """Hypotheses alive after the last step."""
        return len(self.beam)

    def path(self) -> NDArray[np.int64]:
        """The best final hypothesis traced back; a fresh start (-2) continues from the best hypothesis before it."""
        steps = len(self.hist_state)
        path = np.empty(steps, np.int64)
        index = 0
        for t in range(steps - 1, -1, -1):
            path[t] = self.states.edge[self.hist_state[t][index]]
            index = int(self.hist_parent[t][index])
            if index == -2:
                index = 0
        return path


def beam_decode(
    logp: NDArray,
    states: DirectedEdges,
    strategy: str = "strategy1",
    k: int = 5,
    initial: str = "all",
    score: str = "joint",
    reseed: int = 0,
    reseed_penalty: float = 5.0,
    initial_k: int = 5,
) -> Decoded:
    """Multi-hypothesis decoding of ``logp`` ``(T, E)`` on ``states`` (see the module docstring)."""
    logp = np.asarray(logp, dtype=np.float64)
    if len(logp) == 0:
        raise ValueError("no steps to decode")
    beam = Beam(states, strategy, k, initial, score, reseed, reseed_penalty, initial_k)
    answers, alive = [], []
    for t in range(len(logp)):
        answers.append(beam.update(logp[t]))
        alive.append(beam.alive)
    online = np.array([a for a, _ in answers], np.int64)
    confidence = np.array([c for _, c in answers], float)
    return Decoded(online, beam.path(), confidence, beam.initial_edges, beam.restarts, np.asarray(alive, np.int64))


def decode_strategy1(logp: NDArray, states: DirectedEdges, k: int = 5, **options) -> Decoded:
    """Strategy 1: expand every hypothesis along the map, keep the top ``k``."""
    return beam_decode(logp, states, "strategy1", k, **options)


def decode_strategy2(logp: NDArray, states: DirectedEdges, k: int = 5, **options) -> Decoded:
    """Strategy 2: the RNN's top ``k`` per step, less those not connected to a surviving hypothesis."""
    return beam_decode(logp, states, "strategy2", k, **options)
