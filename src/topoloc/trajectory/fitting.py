"""Fitting the trajectory RNN with Lightning (:func:`topoloc.training.fit`, the training path shared with
``train_retrieval``): the network of the config and its training on a DFS dataset."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.training import FitSettings, LoggedModel
from topoloc.training import fit as fit_module
from topoloc.trajectory.model import TrajectoryData, TrajectoryRNN


def build_model(conf: dict[str, Any], num_edges: int, feature_dim: int = 0) -> TrajectoryRNN:
    """The network of ``conf['model']`` with the optimizer of ``conf['train']``."""
    model, train = conf["model"], conf["train"]
    if train["optimizer"] not in ("adam", "sgd"):
        raise InputError("train.optimizer", f"must be adam or sgd, got {train['optimizer']!r}")
    return TrajectoryRNN(
        bins=int(conf["encoding"]["angle_bins"]),
        num_edges=num_edges,
        cell=model["cell"],
        hidden_size=int(model["hidden_size"]),
        embedding_dim=int(model["embedding_dim"]),
        optimizer=train["optimizer"],
        lr=float(train["lr"]),
        weight_decay=float(train["weight_decay"]),
        lr_schedule=train["lr_schedule"],
        plateau_factor=float(train["lr_plateau_factor"]),
        plateau_patience=int(train["lr_plateau_patience"]),
        warmup_fraction=float(train["warmup_fraction"]),
        state_loss_weight=float(train["state_loss_weight"]),
        feature_dim=feature_dim,
    )


def fit(conf: dict[str, Any], train_path: str, val_path: str, num_edges: int, model_path: str,
        fast_dev_run: bool = False, log_model: bool = False,
        feature_dim: int = 0) -> tuple[TrajectoryRNN, pd.DataFrame, dict[str, float]]:
    """Train; write the best checkpoint to ``model_path``; return the model, the history and metrics.

    ``feature_dim``: continuous features per token in the dataset (its ``stats.json``), fed beside the token.

    Inside an active MLflow run the metrics go to it, and with ``log_model`` the model too.
    """
    train = conf["train"]
    bins = int(conf["encoding"]["angle_bins"])
    data = TrajectoryData(train_path, val_path, bins, int(train["batch_size"]), int(train["seed"]),
                          bucket_by_length=bool(train["bucket_by_length"]),
                          state_targets=float(train["state_loss_weight"]) > 0, feature_dim=feature_dim)
    data.setup()
    if len(data.train) == 0:
        raise InputError(train_path, "empty training set (dataset stage produced no training paths)")
    if len(data.val) == 0:
        raise InputError(val_path, "empty validation set (set dataset.val_fraction > 0)")
    patience = train["early_stopping_patience"]
    settings = FitSettings.from_config(train, gradient_clip=train["gradient_clip"], sanity_val_steps=2,
                                       early_stopping_patience=int(patience) if patience is not None else None,
                                       fast_dev_run=fast_dev_run)
    result = fit_module(lambda: build_model(conf, num_edges, feature_dim), data, settings, model_path,
                        logged_model=LoggedModel(signature_example(bins), free_axes=2) if log_model else None)
    metrics = result.metrics | {"train_size": float(len(data.train)), "val_size": float(len(data.val))}
    return result.module, result.history, metrics


def signature_example(bins: int) -> np.ndarray:
    """Two token sequences ``(2, 6)`` int64 for the logged model's signature: straight on, and one turn."""
    return np.array([[bins // 2] * 6, [bins // 2, bins // 2, 3, bins // 2, bins // 2, bins // 2]], dtype=np.int64)
