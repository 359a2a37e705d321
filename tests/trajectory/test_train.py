"""Lightning training: a fast_dev_run, and overfitting a small map to 100% last-step accuracy."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest
import torch

from topoloc.trajectory.dataset import load_sequences
from topoloc.trajectory.evaluate_rnn import accuracy_by_position
from topoloc.trajectory.generate_dataset import generate
from topoloc.trajectory.model import IGNORE, TrajectoryRNN, pad_batch, predict
from topoloc.trajectory.train_rnn import fit
from trajectory_helpers import random_graph


def confs(**train):
    return {
        "encoding": {"angle_bins": 20, "heading_lookahead_m": 10.0},
        "dataset": {"path_nodes": 4, "respect_oneway": False, "max_paths_per_source": None, "max_paths_total": None,
                    "val_fraction": 0.2, "seed": 0, "shard_rows": 64, "augment": {"copies": 0}},
        "model": {"cell": "gru", "hidden_size": 64, "embedding_dim": 16},
        "train": {"optimizer": "adam", "lr": 0.01, "batch_size": 16, "max_epochs": 1, "max_time_min": None,
                  "early_stopping_patience": None, "gradient_clip": 1.0, "seed": 0, "accelerator": "cpu",
                  "log_every_n_steps": 5} | train,
    }


@pytest.fixture
def small_dataset(tmp_path):
    graph = random_graph(3, n=10, extra=5)  # a seed with no ambiguous trajectory
    conf = confs()
    stats = generate(graph, conf, str(tmp_path / "train.parquet"), str(tmp_path / "val.parquet"))
    return graph, stats, tmp_path


def test_padding_and_masked_loss():
    tokens, labels, lengths = pad_batch([(torch.tensor([1, 2, 3]), torch.tensor([4, 4, 5])), (torch.tensor([7]), torch.tensor([6]))], pad_token=20)
    assert tokens.tolist() == [[1, 2, 3], [7, 20, 20]] and labels.tolist() == [[4, 4, 5], [6, IGNORE, IGNORE]]
    assert lengths.tolist() == [3, 1]
    model = TrajectoryRNN(20, 8, cell="rnn")
    # a causal RNN: the outputs of the short sequence do not depend on the padding after it
    alone = model(torch.tensor([[7]]))[0, 0]
    assert torch.allclose(model(tokens)[1, 0], alone, atol=1e-6)


@pytest.mark.parametrize("cell", ["rnn", "gru", "lstm"])
def test_fast_dev_run(small_dataset, cell):
    graph, stats, tmp = small_dataset
    conf = confs()
    conf["model"]["cell"] = cell
    model, history, metrics = fit(conf, str(tmp / "train.parquet"), str(tmp / "val.parquet"), graph.num_edges,
                                  str(tmp / "model.ckpt"), fast_dev_run=True)
    assert (tmp / "model.ckpt").is_file()
    assert model.head.out_features == graph.num_edges and model.hparams.cell == cell
    assert metrics["train_size"] == stats["train_trajectories"]


@pytest.mark.xfail(strict=True, reason="reaches 0.90-0.98 last-step accuracy on this map, not yet 1.0: open (see README)")
def test_overfits_small_map_to_full_last_step_accuracy(small_dataset):
    graph, stats, tmp = small_dataset
    tokens, labels = load_sequences(tmp / "train.parquet")
    last = defaultdict(set)
    for t, lab in zip(tokens, labels):
        last[tuple(t)].add(int(lab[-1]))
    assert all(len(v) == 1 for v in last.values()), "the small map must have no ambiguous trajectories"
    conf = confs(max_epochs=150, batch_size=8, lr=0.01, lr_plateau_factor=0.3, lr_plateau_patience=3)
    conf["model"] |= {"hidden_size": 128, "embedding_dim": 32}
    # validate on the training set itself: the checkpoint with the lowest training loss is kept
    model, history, metrics = fit(conf, str(tmp / "train.parquet"), str(tmp / "train.parquet"), graph.num_edges, str(tmp / "model.ckpt"))
    table = accuracy_by_position(predict(model, tokens), labels)
    assert table.set_index("position").loc["last", "accuracy"] == 1.0
    assert len(history.dropna(subset=["val_loss"])) >= 2
    reloaded = TrajectoryRNN.load_from_checkpoint(tmp / "model.ckpt", map_location="cpu")
    assert all(np.array_equal(a, b) for a, b in zip(predict(reloaded, tokens), predict(model, tokens)))


def test_accuracy_by_position_eq6():
    preds = [np.array([1, 2, 3]), np.array([1, 9])]
    labels = [np.array([1, 2, 4]), np.array([1, 2])]
    table = accuracy_by_position(preds, labels).set_index("position")
    assert table.loc["1"].tolist() == [2, 1.0]
    assert table.loc["2"].tolist() == [2, 0.5]
    assert table.loc["3"].tolist() == [1, 0.0]
    assert table.loc["last"].tolist() == [2, 0.0]
