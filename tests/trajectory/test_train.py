"""Lightning training: a fast_dev_run, overfitting a small map to 100% last-step accuracy, the causal ceiling."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from trajectory_helpers import random_graph

from tests.conftest import make_config
from topoloc.trajectory.dataset import load_sequences
from topoloc.trajectory.accuracy import accuracy_by_position, prefix_majority
from topoloc.trajectory.generate_dataset import generate
from topoloc.trajectory.model import IGNORE, LengthBucketBatches, TrajectoryRNN, pad_batch, predict
from topoloc.trajectory.fitting import build_model, fit


def confs(**train):
    """The config of a small, fast training (schema defaults otherwise), ``train`` keys on top."""
    return make_config(
        dataset={"source": "dfs", "path_nodes": 4, "respect_oneway": False, "val_fraction": 0.2, "shard_rows": 64},
        model={"cell": "gru", "hidden_size": 64, "embedding_dim": 16},
        train={"batch_size": 16, "max_epochs": 1, "max_time_min": None, "early_stopping_patience": None,
               "gradient_clip": 1.0, "accelerator": "cpu", "log_every_n_steps": 5, **train},
    )

def test_schema_defaults_reach_the_model():
    """A config from load() with no override builds the pipeline's model: no code default stands in between."""
    config = make_config()
    assert config["train"]["lr_schedule"] == "onecycle" and config["train"]["state_loss_weight"] == 0.5
    model = build_model(config, num_edges=7)
    assert model.hparams.lr_schedule == "onecycle"
    assert model.hparams.state_loss_weight == 0.5 and hasattr(model, "state_head")
    assert model.hparams.warmup_fraction == config["train"]["warmup_fraction"]
    assert (model.hparams.cell, model.hparams.hidden_size) == ("lstm", config["model"]["hidden_size"])

@pytest.fixture
def small_dataset(tmp_path):
    # a seed whose trajectories are unambiguous at every last step, even to a model that sees only a prefix
    graph = random_graph(9, n=10, extra=5)
    conf = confs()
    stats = generate(graph, conf, str(tmp_path / "train.parquet"), str(tmp_path / "val.parquet"))
    return graph, stats, tmp_path

def test_padding_and_masked_loss():
    tokens, labels, lengths, inputs = pad_batch([(torch.tensor([1, 2, 3]), torch.tensor([4, 4, 5]), torch.ones(3, 2)),
                                                 (torch.tensor([7]), torch.tensor([6]), torch.ones(1, 2))], pad_token=20)
    assert inputs.shape == (2, 3, 2) and inputs[1, 1:].abs().sum() == 0  # features padded with zeros
    assert tokens.tolist() == [[1, 2, 3], [7, 20, 20]] and labels.tolist() == [[4, 4, 5], [6, IGNORE, IGNORE]]
    assert lengths.tolist() == [3, 1]
    model = TrajectoryRNN(20, 8, cell="rnn")
    # a causal RNN: the outputs of the short sequence do not depend on the padding after it
    alone = model(torch.tensor([[7]]))[0, 0]
    assert torch.allclose(model(tokens)[1, 0], alone, atol=1e-6)

def test_length_buckets_cover_every_sequence_once_per_epoch():
    lengths = [5, 40, 7, 33, 12, 12, 90, 3, 18, 27]
    sampler = LengthBucketBatches(lengths, 3, torch.Generator().manual_seed(0), window_batches=2)
    epochs = [list(sampler), list(sampler)]
    for batches in epochs:
        assert sorted(i for batch in batches for i in batch) == list(range(len(lengths)))
        assert len(batches) == len(sampler) == 4
        for batch in batches:  # sorted by length inside each batch (windows are sorted before cutting)
            assert [lengths[i] for i in batch] == sorted(lengths[i] for i in batch)
    assert epochs[0] != epochs[1]  # a new order every epoch
    again = LengthBucketBatches(lengths, 3, torch.Generator().manual_seed(0), window_batches=2)
    assert list(again) == epochs[0]  # ... from the seed


@pytest.mark.parametrize(("cell", "state_loss_weight"), [("rnn", 0.0), ("gru", 0.5), ("lstm", 0.5)])
def test_fast_dev_run(small_dataset, cell, state_loss_weight):
    graph, stats, tmp = small_dataset
    conf = confs(state_loss_weight=state_loss_weight)
    conf["model"]["cell"] = cell
    model, history, metrics = fit(conf, str(tmp / "train.parquet"), str(tmp / "val.parquet"), graph.num_edges,
                                  str(tmp / "model.ckpt"), fast_dev_run=True)
    assert (tmp / "model.ckpt").is_file()
    assert model.head.out_features == graph.num_edges and model.hparams.cell == cell
    assert hasattr(model, "state_head") == (state_loss_weight > 0)
    assert metrics["train_size"] == stats["train_trajectories"]

def test_overfits_small_map_to_full_last_step_accuracy(small_dataset):
    graph, stats, tmp = small_dataset
    tokens, labels = load_sequences(tmp / "train.parquet")
    best = accuracy_by_position(prefix_majority(tokens, labels, tokens), labels).set_index("position")
    assert best.loc["last", "accuracy"] == 1.0, "the small map must have no ambiguous last steps"
    conf = confs(max_epochs=100, batch_size=8, lr=0.01, lr_schedule="onecycle")
    conf["model"] |= {"cell": "lstm", "hidden_size": 128, "embedding_dim": 32}
    # validate on the training set itself: the checkpoint with the lowest training loss is kept
    model, history, metrics = fit(conf, str(tmp / "train.parquet"), str(tmp / "train.parquet"), graph.num_edges, str(tmp / "model.ckpt"))
    table = accuracy_by_position(predict(model, tokens), labels)
    assert table.set_index("position").loc["last", "accuracy"] == 1.0
    assert len(history.dropna(subset=["val/loss"])) >= 2
    assert metrics["best/val/loss"] == pytest.approx(history["val/loss"].min())
    reloaded = TrajectoryRNN.load_from_checkpoint(tmp / "model.ckpt", map_location="cpu")
    assert all(np.array_equal(a, b) for a, b in zip(predict(reloaded, tokens), predict(model, tokens)))

def test_prefix_majority_is_the_causal_ceiling():
    tokens = [np.array([10, 10, 5]), np.array([10, 10, 5, 10]), np.array([10, 15])]
    labels = [np.array([1, 1, 2]), np.array([1, 3, 4, 4]), np.array([1, 6])]
    # after [10, 10] the edge is 1 or 3 (one each: the lower id wins); after [10, 10, 5] it is 2 or 4
    guesses = prefix_majority(tokens, labels, tokens + [np.array([7])])
    assert [g.tolist() for g in guesses] == [[1, 1, 2], [1, 1, 2, 4], [1, 6], [-1]]
    table = accuracy_by_position(guesses[:3], labels).set_index("position")
    assert table.loc["2", "accuracy"] == pytest.approx(2 / 3)  # the second sequence is on edge 3: no causal model knows
    assert table.loc["3", "accuracy"] == pytest.approx(1 / 2)
    assert table.loc["last", "accuracy"] == 1.0

def test_accuracy_by_position_eq6():
    preds = [np.array([1, 2, 3]), np.array([1, 9])]
    labels = [np.array([1, 2, 4]), np.array([1, 2])]
    table = accuracy_by_position(preds, labels).set_index("position")
    assert table.loc["1"].tolist() == [2, 1.0]
    assert table.loc["2"].tolist() == [2, 0.5]
    assert table.loc["3"].tolist() == [1, 0.0]
    assert table.loc["last"].tolist() == [2, 0.0]
