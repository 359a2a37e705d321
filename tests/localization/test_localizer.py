"""The localizer interface: the registry, and every localizer's online updates against its batch algorithm."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from localization_helpers import irregular_grid

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.localization.decoders import beam_decode
from topoloc.localization.hmm import CellHMM, HmmParams
from topoloc.localization.rnn import edge_log_probs
from topoloc.localization.roadmap import RoadMap
from topoloc.localizer import Answer, Localizer, register
from topoloc.motion.poses import Odometry
from topoloc.registry import check_names, make, registry
from topoloc.trajectory.model import TrajectoryRNN


@pytest.fixture(scope="module")
def setting():
    graph, _ = irregular_grid()
    torch.manual_seed(0)
    model = TrajectoryRNN(20, graph.num_edges, cell="lstm", hidden_size=16, embedding_dim=8).eval()
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    conf["localization"]["rnn"] |= {"window": 12, "stride": 4}  # several windows on a short token sequence
    tokens = [int(t) for t in np.random.default_rng(0).integers(0, 20, 40)]
    return graph, RoadMap(graph, model=model), conf, tokens


def test_registry_names_labels_and_needs():
    known = registry()
    assert {"raw", "strategy1", "strategy2", "hmm", "metric"} <= set(known)
    assert all(cls.label and cls.observes in ("tokens", "odometry", "images") for cls in known.values())
    assert {n for n, cls in known.items() if cls.requires_model} >= {"raw", "strategy1", "strategy2"}
    assert not known["metric"].requires_model and not known["hmm"].requires_model
    with pytest.raises(InputError, match=r"^--decoder.1: unknown localizer 'kalman'; choose from \["):
        check_names(["metric", "kalman"], "--decoder")


def test_register_rejects_incomplete_or_duplicate_localizers():
    class Nameless(Localizer):
        def start(self): ...
        def update(self, observation): return Answer(-1, 0.0)
        def answer(self): return Answer(-1, 0.0)

    with pytest.raises(TypeError, match="needs a name"):
        register(Nameless)
    twin = type("Twin", (Nameless,), {"name": "metric", "label": "twin", "observes": "odometry"})
    with pytest.raises(TypeError, match="two localizers are named 'metric'"):
        register(twin)


@pytest.mark.parametrize("name", ["strategy1", "strategy2"])
def test_beam_localizers_online_equal_the_batch_decoder(setting, name):
    graph, road, conf, tokens = setting
    localizer = make(name)
    localizer.reset(road, conf)
    track = localizer.run(tokens)
    logp = edge_log_probs(road.model, np.asarray(tokens), 12, 4)
    dec = conf["localization"]["decode"]
    batch = beam_decode(logp, road.states, name, dec["k"], initial=dec["initial_hypotheses"], score=dec["score"],
                        reseed=dec["reseed"], reseed_penalty=dec["reseed_penalty"])
    assert track.state.tolist() == batch.online.tolist() and track.path.tolist() == batch.path.tolist()
    assert np.allclose(track.confidence, batch.confidence, atol=1e-5)
    raw = make("raw")
    raw.reset(road, conf)
    assert raw.run(tokens).state.tolist() == np.argmax(logp, axis=1).tolist()


def test_hmm_localizer_online_equals_the_batch_decode(setting):
    graph, road, conf, tokens = setting
    localizer = make("hmm")
    unmerged = {**conf, "localization": {**conf["localization"], "places": {**conf["localization"]["places"], "top": 3, "merge_m": 0.0}}}
    localizer.reset(road, unmerged)
    track = localizer.run(tokens)
    batch = CellHMM(graph, road.states, 20, HmmParams.from_conf(conf["localization"]["hmm"])).run(np.asarray(tokens))
    assert track.state.tolist() == batch.online.tolist() and track.path.tolist() == batch.path.tolist()
    assert np.allclose(track.confidence, batch.confidence)
    assert np.isfinite(track.xy).all()  # the HMM's cells give a position
    # places within merge_m are one: the answer's confidence is the merged place's mass, never less than its road's
    localizer.reset(road, conf)
    merged = localizer.run(tokens)
    assert (merged.confidence >= batch.confidence - 1e-9).all() and (merged.confidence > batch.confidence + 1e-6).any()
    assert all(abs(a.confidence - p[0].probability) < 1e-12 and p[0].state == s for a, p, s in
               zip([localizer.answer()], [merged.places[-1]], [merged.state[-1]]))


def test_reset_restarts_and_keeps_the_map_structures(setting):
    graph, road, conf, tokens = setting
    localizer = make("hmm")
    localizer.reset(road, conf)
    first = localizer.run(tokens)
    hmm = localizer.hmm
    localizer.reset(road, conf)
    again = localizer.run(tokens)
    assert localizer.hmm is hmm and first.state.tolist() == again.state.tolist()


def test_run_starts_sees_nothing_before_the_start(setting):
    graph, road, conf, _ = setting
    xy = np.column_stack([np.arange(0.0, 90.0), np.zeros(90)])
    odometry = Odometry(xy, np.zeros(90))
    runs = make("metric").run_starts(odometry, road, conf, np.array([0, 30, 60]))
    assert [start for start, _, _ in runs] == [0, 30, 60]
    for start, observations, track in runs:
        assert observations.frame.min() > start and len(track) == len(observations)
        assert len(track) == pytest.approx((89 - start) / 2.0, abs=1.0)  # a step every 2 m from the start
