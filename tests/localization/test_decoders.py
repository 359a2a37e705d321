"""Connectivity of directed edges and the raw / Strategy 1 / Strategy 2 decoders on hand-made logits."""

from __future__ import annotations

import numpy as np
import pytest
from localization_helpers import make_graph, peaked_logits

from topoloc.localization.connectivity import consecutive_connected, directed_edges
from topoloc.localization.decoders import beam_decode, decode_raw, log_softmax


def test_successors_respect_direction_one_way_and_dead_ends(corridor):
    st = directed_edges(corridor)
    assert st.valid.tolist() == [True, True, True, False, True, True, True, True, True, True]  # edge 1 only 1 -> 2
    assert st.successors[0][st.successors[0] >= 0].tolist() == [0, 2]  # 0->1, then stay or take edge 1 onwards
    assert st.successors[2][st.successors[2] >= 0].tolist() == [2, 4]
    assert st.successors[4][st.successors[4] >= 0].tolist() == [4, 5]  # dead end at 3: U-turn allowed there
    # 3 -> 2 cannot enter one-way edge 1 against its direction: no way on, so turning back is allowed
    assert st.successors[5][st.successors[5] >= 0].tolist() == [5, 4]
    never = directed_edges(corridor, u_turns="never")
    assert never.successors[4][never.successors[4] >= 0].tolist() == [4]
    always = directed_edges(corridor, u_turns="always")
    assert always.successors[0][always.successors[0] >= 0].tolist() == [0, 1, 2]  # back on edge 0, or on
    assert always.successors[6][always.successors[6] >= 0].tolist() == [6, 7, 8]  # 4 -> 5: on, or back


def test_short_roads_can_be_crossed_within_one_step():
    coords = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (108.0, 0.0), 3: (208.0, 0.0)}
    graph = make_graph(coords, [(0, 1), (1, 2), (2, 3)])  # edge 1 is 8 m, shorter than the 20 m spacing
    st = directed_edges(graph)
    assert set(st.successors[0][st.successors[0] >= 0].tolist()) == {0, 2, 4}
    assert consecutive_connected(st, np.array([0, 2, 1])).tolist() == [True, True]
    assert directed_edges(graph, max_skip_m=5.0).successors[0].tolist().count(4) == 0


def test_strategy1_repairs_a_disconnected_raw_guess(corridor):
    truth = np.array([0, 0, 0, 1, 1, 1, 2, 2])
    # step 3: the RNN prefers edge 4, far away and not connected to anything the vehicle was on
    logp = log_softmax(peaked_logits(truth, 5, {3: {4: 5.0}}))
    raw = decode_raw(logp)
    assert raw.path[3] == 4 and not consecutive_connected(directed_edges(corridor), raw.path).all()
    s1 = beam_decode(logp, directed_edges(corridor), "strategy1", k=5)
    assert s1.path.tolist() == truth.tolist()
    assert consecutive_connected(directed_edges(corridor), s1.path).all()
    assert s1.online.tolist() == truth.tolist()  # no hypothesis on the far corridor survived to step 3


def test_strategy2_loses_the_truth_outside_the_top_k(corridor):
    st = directed_edges(corridor)
    truth = np.array([0, 0, 0, 1, 1, 1, 2, 2])
    # step 3: edges 3 and 4 (far away) outrank the true edge 1, which is third: outside the top k = 2
    logp = log_softmax(peaked_logits(truth, 5, {3: {3: 5.0, 4: 4.5, 1: 4.0, 0: 0.0}}))
    s2 = beam_decode(logp, st, "strategy2", k=2)
    # no top-2 edge connects to a surviving hypothesis: it starts over on the far corridor at step 3,
    # and over again at step 4, where the far corridor is not in the top 2
    assert s2.restarts == 2
    assert s2.path.tolist() == [0, 0, 0, 3, 1, 1, 2, 2] and not consecutive_connected(st, s2.path).all()
    s1 = beam_decode(logp, st, "strategy1", k=2)
    assert s1.path.tolist() == truth.tolist() and s1.restarts == 0


@pytest.mark.parametrize("score", ["joint", "conditional"])
def test_beam_of_all_states_is_exact_and_scores_agree(corridor, score):
    st = directed_edges(corridor)
    truth = np.array([3, 3, 4, 4, 4])
    logp = log_softmax(peaked_logits(truth, 5, {1: {0: 4.5}}))
    for k in (1, 3, st.num_states):
        dec = beam_decode(logp, st, "strategy1", k=k, score=score)
        assert dec.path.tolist() == truth.tolist()
        assert consecutive_connected(st, dec.path).all()
        assert len(dec.initial) <= 5 and dec.hypotheses.max() <= max(k, st.valid.sum())


def test_reseeding_relocalizes_after_a_wrong_start(corridor):
    st = directed_edges(corridor)
    # the first steps point at the far corridor (edges 3, 4); the vehicle is really on 0 -> 1 -> 2
    truth = np.array([0] * 4 + [1] * 6 + [2] * 6)
    logits = peaked_logits(truth, 5, {t: {3: 6.0} for t in range(4)})
    logp = log_softmax(logits)
    plain = beam_decode(logp, st, "strategy1", k=1, initial="top_k")
    assert (plain.online[-6:] != truth[-6:]).all()  # one hypothesis on the far corridor can never come back
    seeded = beam_decode(logp, st, "strategy1", k=1, initial="top_k", reseed=2, reseed_penalty=3.0)
    assert seeded.online[-6:].tolist() == truth[-6:].tolist() and seeded.restarts >= 1
