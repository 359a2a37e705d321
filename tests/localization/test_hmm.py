"""The HMM baseline recovers a noiseless route on a small grid-like map."""

from __future__ import annotations

import numpy as np
from localization_helpers import irregular_grid

from topoloc.config import load
from topoloc.localization.connectivity import consecutive_connected, directed_edges
from topoloc.localization.evaluation import localized_step
from topoloc.localization.hmm import CellHMM, HmmParams
from topoloc.trajectory.dataset import PathEncoder
from topoloc.trajectory.paths import Path

PARAMS = HmmParams.from_conf(load(None)["localization"]["hmm"])


def route_tokens(graph, edges, nodes):
    index = {frozenset(e): k for k, e in enumerate(edges)}
    path = Path(tuple(nodes), tuple(index[frozenset((a, b))] for a, b in zip(nodes[:-1], nodes[1:])))
    return PathEncoder(graph, 20, 10.0).encode(path)


def test_hmm_recovers_a_noiseless_route_on_a_grid():
    graph, edges = irregular_grid()
    tokens, labels = route_tokens(graph, edges, [0, 1, 6, 7, 8, 13, 14, 9, 4])
    states = directed_edges(graph)
    hmm = CellHMM(graph, states, 20, PARAMS)
    dec = hmm.run(tokens)
    assert dec.path.tolist() == labels.tolist()  # the Viterbi path is the route, from the first step
    assert consecutive_connected(states, dec.path).all()
    distance = 20.0 * np.arange(len(tokens))
    step = localized_step(dec.online == labels, distance, confirm_m=100.0)
    assert distance[step] < 0.7 * distance[-1] and (dec.online[step:] == labels[step:]).all()  # online: sure before the end
    assert dec.confidence[-1] > 0.5 and np.isfinite(dec.extra["log_evidence"])


def test_hmm_mass_stays_on_the_allowed_direction():
    graph, edges = irregular_grid()
    states = directed_edges(graph)
    hmm = CellHMM(graph, states, 20, PARAMS)
    assert hmm.num_cells >= 2 * graph.edges.length_m.sum() / 5.0 - 1e-6
    # moves never lead off the map, and probabilities of one token from one cell sum to at most one
    straight = np.bincount(hmm.src, weights=hmm.weights.sum(axis=0), minlength=hmm.num_cells)
    assert (straight <= 1.0 + 1e-5).all() and (straight > 0.5).all()
