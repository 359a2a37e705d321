"""The learned localizer decoded on the map (rnn_filter): the HMM when the RNN has no say, the RNN's evidence otherwise."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from localization_helpers import irregular_grid

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.localization.rnn import OnlineRNN, edge_log_probs
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.registry import make, registry
from topoloc.trajectory.model import TrajectoryRNN


@pytest.fixture(scope="module")
def setting():
    graph, _ = irregular_grid()
    torch.manual_seed(0)
    model = TrajectoryRNN(20, graph.num_edges, cell="lstm", hidden_size=16, embedding_dim=8, feature_dim=3).eval()
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    # a drive along the bottom row then up the right side: x 0 -> 400 at y = 0, then y 0 -> 340 at x = 400
    xy = np.vstack([np.column_stack([np.arange(0.0, 400.0), np.zeros(400)]),
                    np.column_stack([np.full(340, 400.0), np.arange(0.0, 340.0)])])
    return graph, model, conf, Odometry.from_track(xy)


def test_observations_carry_features_and_the_online_rnn_equals_the_batch(setting):
    graph, model, conf, odometry = setting
    road = RoadMap(graph, model=model)
    localizer = make("rnn_filter")
    obs = localizer.observe(odometry, road, conf)
    assert registry()["rnn_filter"].requires_model and len(obs) > 10
    tokens = np.array([t for t, _ in obs.items])
    inputs = np.stack([f for _, f in obs.items])
    assert inputs.shape == (len(tokens), 3) and inputs[:, 0].sum() * graph.virtual_node_spacing_m == pytest.approx(740, rel=0.05)
    online = OnlineRNN(model)
    steps = np.stack([online.update(int(t), f) for t, f in zip(tokens, inputs)])
    assert np.allclose(steps, edge_log_probs(model, tokens, inputs=inputs), atol=1e-5)
    assert not np.allclose(steps, edge_log_probs(model, tokens))  # without the features the outputs differ


def test_without_evidence_it_is_the_hmm_and_with_it_it_follows_the_rnn(setting):
    graph, model, conf, odometry = setting
    road = RoadMap(graph, model=model)
    hmm, learned = make("hmm"), make("rnn_filter")
    obs = learned.observe(odometry, road, conf)
    silent = {**conf, "localization": {**conf["localization"], "rnn_filter": {**conf["localization"]["rnn_filter"],
                                                                              "evidence_weight": 0.0}}}
    learned.reset(road, silent)
    track = learned.run(obs.items)
    hmm.reset(road, conf)
    base = hmm.run([t for t, _ in obs.items])
    assert track.state.tolist() == base.state.tolist() and track.path.tolist() == base.path.tolist()
    assert learned.explained(obs.items) == hmm.explained([t for t, _ in obs.items])
    # a model sure of road 7 whatever it sees: with full weight the filter ends there, the HMM elsewhere
    sure = TrajectoryRNN(20, graph.num_edges, cell="lstm", hidden_size=16, embedding_dim=8, feature_dim=3).eval()
    with torch.no_grad():
        sure.head.weight.zero_()
        sure.head.bias.zero_()
        sure.head.bias[7] = 20.0
    loud = {**conf, "localization": {**conf["localization"], "rnn_filter": {**conf["localization"]["rnn_filter"],
                                                                            "evidence_weight": 1.0}}}
    other = make("rnn_filter")
    other.reset(RoadMap(graph, model=sure), loud)
    track = other.run(obs.items)
    assert track.state[-1] == 7 != base.state[-1]
    # its answers rank places as the HMM's do: the answer is the top one, the road the model is sure of
    places = track.places[-1]
    assert places[0].state == 7 and places[0].probability == pytest.approx(track.confidence[-1]) and len(places) <= 3
    assert all(a.probability >= b.probability for a, b in zip(places, places[1:]))


def test_a_model_of_another_map_is_refused(setting):
    graph, _, conf, _ = setting
    wrong = TrajectoryRNN(20, graph.num_edges + 3, cell="lstm", hidden_size=8, embedding_dim=4)
    with pytest.raises(InputError, match=r"^model: the model predicts .* edge classes"):
        make("rnn_filter").reset(RoadMap(graph, model=wrong), conf)


def test_map_checked_confidence_is_sure_only_where_the_map_alone_agrees(setting):
    """A model sure of road 7 whatever it sees: with its own confidence the filter ends sure of road 7, off the
    drive; with ``map_checked`` the same answer is only as sure as the mean of that and the map alone's (the HMM's)
    mass on road 7; without the RNN's say the confidence is the map's own."""
    graph, _, conf, odometry = setting
    sure = TrajectoryRNN(20, graph.num_edges, cell="lstm", hidden_size=16, embedding_dim=8, feature_dim=3).eval()
    with torch.no_grad():
        sure.head.weight.zero_()
        sure.head.bias.zero_()
        sure.head.bias[7] = 20.0
    road = RoadMap(graph, model=sure)

    def with_settings(**rnn_filter):
        return {**conf, "localization": {**conf["localization"],
                                         "rnn_filter": {**conf["localization"]["rnn_filter"], **rnn_filter}}}

    own, checked, hmm = make("rnn_filter"), make("rnn_filter"), make("hmm")
    obs = own.observe(odometry, road, conf)
    own.reset(road, with_settings(evidence_weight=1.0, confidence="filter"))
    checked.reset(road, with_settings(evidence_weight=1.0, confidence="map_checked"))
    a, b = own.run(obs.items), checked.run(obs.items)
    hmm.reset(road, conf)
    base = hmm.run([t for t, _ in obs.items])
    assert a.state.tolist() == b.state.tolist() and a.state[-1] == 7 != base.state[-1]
    assert a.confidence[-1] > 0.9 and b.confidence[-1] < 0.6
    assert np.all(b.confidence <= a.confidence + 1e-12)
    hmm_mass_on_7 = [p.probability for p in hmm.hmm.top_places(50) if p.state == 7]
    mass = hmm_mass_on_7[0] if hmm_mass_on_7 else 0.0
    assert b.confidence[-1] == pytest.approx(0.5 * (a.confidence[-1] + mass), abs=1e-4)  # mass: merged places
    # without the RNN's say the two filters are one: the confidence is the map's own
    silent = make("rnn_filter")
    silent.reset(road, with_settings(evidence_weight=0.0, confidence="map_checked"))
    assert np.allclose(silent.run(obs.items).confidence, base.confidence)
    with pytest.raises(InputError, match="localization.rnn_filter.confidence"):
        make("rnn_filter").reset(road, with_settings(confidence="both"))
