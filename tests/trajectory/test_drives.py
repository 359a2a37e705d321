"""Simulated training drives: encoded like test drives, overfit on a tiny map, a model with features through MLflow."""

from __future__ import annotations

import json

import numpy as np
import pytest
from trajectory_helpers import random_graph

from tests.conftest import make_config
from topoloc.errors import InputError
from topoloc.geometry import bin_centre, straight_token
from topoloc.localization.roadmap import RoadMap, token_observations
from topoloc.motion.poses import Odometry
from topoloc.odometry.simulate import simulate_pattern_drive
from topoloc.trajectory.accuracy import (
    accuracy_by_distance,
    accuracy_by_position,
    driven_metres,
    prefix_majority,
)
from topoloc.trajectory.dataset import load_features, load_sequences, load_state_targets
from topoloc.trajectory.drives import noise_level, training_drives
from topoloc.trajectory.fitting import fit
from topoloc.trajectory.generate_dataset import generate, run
from topoloc.trajectory.model import TrajectoryRNN, predict

NOISE = {"scale_error": [0.0, 0.02], "distance_noise": [0.0, 0.02], "heading_drift_deg_per_100m": [0.0, 1.0],
         "heading_noise_deg": [0.0, 0.05]}


def drive_conf(drives: int = 30, length=(300.0, 600.0), crop_m: float = 0.0, **train):
    """A small simulated-drives dataset and training config."""
    return make_config(
        dataset={"source": "simulated_drives", "val_fraction": 0.2, "shard_rows": 16,
                 "simulated": {"drives": drives, "length_m": list(length), "crop_m": crop_m, "noise": NOISE}},
        model={"cell": "lstm", "hidden_size": 64, "embedding_dim": 16},
        train={"batch_size": 8, "max_epochs": 1, "max_time_min": None, "early_stopping_patience": None,
               "accelerator": "cpu", "log_every_n_steps": 5, "log_model": False, **train},
    )


def token_stats(tokens: list[np.ndarray], metres: float, bins: int = 20) -> tuple[float, float, float, float]:
    """Tokens per 100 m, the share of turn tokens, their mean absolute turn (degrees) and the share of left turns."""
    flat = np.concatenate(tokens)
    turns = flat[flat != straight_token(bins)]
    delta = 180.0 - np.asarray(bin_centre(turns, bins))  # signed turn, left positive
    return 100.0 * len(flat) / metres, len(turns) / len(flat), float(np.abs(delta).mean()), float(np.mean(delta > 0))


def test_training_drives_have_the_token_statistics_of_test_drives():
    """Training drives and test drives (the localization benchmark's simulated drives, tokens made by the
    localizers' own observe step) of one map and noise agree on token rate, turn share and turn angles."""
    graph = random_graph(3, n=14, extra=8)
    conf = drive_conf(drives=40)
    train = list(training_drives(graph, conf, seed=0))
    assert len(train) == 40
    road, rng = RoadMap(graph), np.random.default_rng(7)
    test_tokens, test_metres = [], 0.0
    for _ in range(40):
        drive = simulate_pattern_drive(graph, float(rng.uniform(300, 600)), noise_level(NOISE), rng)
        obs = token_observations(Odometry(drive.odometry.xy, drive.odometry.yaw), road, conf, 20)
        test_tokens.append(np.asarray(obs.items))
        test_metres += drive.length_m
    rate_a, share_a, turn_a, left_a = token_stats([d.tokens for d in train], sum(d.length_m for d in train))
    rate_b, share_b, turn_b, left_b = token_stats(test_tokens, test_metres)
    assert rate_a == pytest.approx(rate_b, rel=0.1)
    assert share_a == pytest.approx(share_b, abs=0.04)
    assert turn_a == pytest.approx(turn_b, abs=12.0) and left_a == pytest.approx(left_b, abs=0.15)
    for drive in train:  # labels are roads of the walk, features one row per token, distances add up to the drive
        assert set(drive.labels.tolist()) <= set(drive.edges) and drive.features.shape == (len(drive.tokens), 3)
        assert drive.features[:, 0].sum() * graph.virtual_node_spacing_m <= drive.length_m * 1.1
    again = list(training_drives(graph, conf, seed=0))
    assert all(np.array_equal(a.tokens, b.tokens) and np.array_equal(a.features, b.features) for a, b in zip(train, again))


def test_dataset_files_of_simulated_drives(tmp_path):
    graph = random_graph(3, n=14, extra=8)
    graph.save_graphml(tmp_path / "graph.graphml")
    outputs = {"train": str(tmp_path / "t.parquet"), "val": str(tmp_path / "v.parquet"),
               "stats": str(tmp_path / "stats.json"), "table": str(tmp_path / "table_i.md")}
    metrics = run(drive_conf(drives=20, crop_m=100.0), {"graph": str(tmp_path / "graph.graphml")}, outputs)
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["trajectories"] == 20 == stats["train_trajectories"] + stats["val_trajectories"] == metrics["trajectories"]
    assert stats["feature_dim"] == 3 and stats["source"] == "simulated_drives"
    assert all(isinstance(v, float) for v in metrics.values())  # MLflow metrics: numbers only
    assert "tokens + 3 continuous features" in (tmp_path / "table_i.md").read_text()
    tokens, labels = load_sequences(tmp_path / "t.parquet")
    features = load_features(tmp_path / "t.parquet", 3)
    assert [len(f) for f in features] == [len(t) for t in tokens] == [len(x) for x in labels]
    directions, _ = load_state_targets(tmp_path / "t.parquet")
    assert [len(d) for d in directions] == [len(t) for t in tokens]
    with pytest.raises(InputError, match=r"^dataset.simulated.noise.scale_error: expected \[low, high\]"):
        noise_level({**NOISE, "scale_error": [0.03, 0.01]})


def test_overfits_tiny_map_drives_where_the_tokens_tell(tmp_path):
    """On a tiny map's training drives the model is right at the last token of every drive whose tokens alone
    (the causal ceiling from tokens, less than the model sees) single out the road."""
    graph = random_graph(9, n=10, extra=5)
    conf = drive_conf(drives=16, length=(200.0, 400.0), max_epochs=300, lr=0.02, batch_size=4, state_loss_weight=0.0)
    stats = generate(graph, conf, str(tmp_path / "train.parquet"), str(tmp_path / "val.parquet"))
    tokens, labels = load_sequences(tmp_path / "train.parquet")
    features = load_features(tmp_path / "train.parquet", 3)
    ceiling = prefix_majority(tokens, labels, tokens)
    possible = [i for i, (c, y) in enumerate(zip(ceiling, labels)) if c[-1] == y[-1]]
    assert len(possible) >= len(tokens) // 2
    model, _, _ = fit(conf, str(tmp_path / "train.parquet"), str(tmp_path / "train.parquet"), graph.num_edges,
                      str(tmp_path / "model.ckpt"), feature_dim=stats["feature_dim"])
    pred = predict(model, tokens, inputs=features)
    assert all(pred[i][-1] == labels[i][-1] for i in possible)
    every = np.mean(np.concatenate([p == y for p, y in zip(pred, labels)]))
    assert every >= np.mean(np.concatenate([c == y for c, y in zip(ceiling, labels)])) - 0.02  # every step: the ceiling too
    table = accuracy_by_distance(pred, labels, driven_metres(features, graph.virtual_node_spacing_m))
    assert table.n.sum() == sum(len(t) for t in tokens)
    assert table.accuracy.iloc[-1] > table.accuracy.iloc[0]  # the longer the drive, the surer
    assert accuracy_by_position(pred, labels).set_index("position").loc["last", "accuracy"] >= len(possible) / len(tokens)


def test_feature_model_round_trips_through_mlflow(tmp_path, monkeypatch):
    import mlflow
    import torch

    from topoloc.training import LoggedModel, log_model
    from topoloc.trajectory.model import load_model, log_checkpoint
    from topoloc.trajectory.fitting import signature_example

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    mlflow.set_tracking_uri(uri)
    graph = random_graph(3, n=14, extra=8)
    conf = drive_conf(drives=12)
    stats = generate(graph, conf, str(tmp_path / "t.parquet"), str(tmp_path / "v.parquet"))
    model, _, _ = fit(conf, str(tmp_path / "t.parquet"), str(tmp_path / "v.parquet"), graph.num_edges,
                      str(tmp_path / "model.ckpt"), fast_dev_run=True, feature_dim=stats["feature_dim"])
    model = model.eval()
    with mlflow.start_run() as run:
        log_model(model, LoggedModel(signature_example(20), free_axes=2))
        log_checkpoint(tmp_path / "model.ckpt")
    loaded = load_model(f"runs:/{run.info.run_id}/model", tracking_uri=uri)
    assert isinstance(loaded, TrajectoryRNN) and load_model(run.info.run_id, tracking_uri=uri).hparams == loaded.hparams
    tokens = [np.array([10, 10, 3, 10, 17]), np.array([10, 5])]  # drive-like token sequences
    inputs = [np.random.default_rng(1).normal(size=(len(t), 3)).astype(np.float32) for t in tokens]
    assert int(loaded.hparams.feature_dim) == 3
    with torch.no_grad():
        for t, f in zip(tokens, inputs):
            a = model(torch.as_tensor(t)[None], torch.as_tensor(f)[None])
            b = loaded(torch.as_tensor(t)[None], torch.as_tensor(f)[None])
            assert torch.allclose(a, b)
            assert not torch.allclose(a, model(torch.as_tensor(t)[None]))  # the features reach the output
