"""Stage ``train_rnn``: fit the trajectory RNN on the DFS dataset with Lightning.

Logged to the stage's MLflow run through Lightning's MLFlowLogger bound to
that run; the best checkpoint (lowest validation loss) is written to
``model`` and logged as an MLflow PyTorch model with its signature.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import pandas as pd
import torch

from topoloc.encoding import check_encoding
from topoloc.errors import InputError
from topoloc.io import atomic_path, write_json
from topoloc.tracking import tracking_uri
from topoloc.training import History, best_checkpoint, keep_best
from topoloc.trajectory.model import TrajectoryData, TrajectoryRNN

log = logging.getLogger(__name__)


def build_model(conf: dict[str, Any], num_edges: int) -> TrajectoryRNN:
    """The network of ``conf['model']`` with the optimizer of ``conf['train']``."""
    model, train = conf["model"], conf["train"]
    if train["optimizer"] not in ("adam", "sgd"):
        raise InputError("train.optimizer", f"must be adam or sgd, got {train['optimizer']!r}")
    return TrajectoryRNN(
        bins=check_encoding(conf["encoding"]),
        num_edges=num_edges,
        cell=model["cell"],
        hidden_size=int(model["hidden_size"]),
        embedding_dim=int(model["embedding_dim"]),
        optimizer=train["optimizer"],
        lr=float(train["lr"]),
        weight_decay=float(train.get("weight_decay", 0.0)),
        lr_schedule=train.get("lr_schedule", "constant"),
        plateau_factor=float(train.get("lr_plateau_factor", 0.3)),
        plateau_patience=int(train.get("lr_plateau_patience", 1)),
        warmup_fraction=float(train.get("warmup_fraction", 0.15)),
        state_loss_weight=float(train.get("state_loss_weight", 0.0)),
    )


def fit(conf: dict[str, Any], train_path: str, val_path: str, num_edges: int, model_path: str,
        logger: Any = None, fast_dev_run: bool = False) -> tuple[TrajectoryRNN, pd.DataFrame, dict[str, float]]:
    """Train; write the best checkpoint to ``model_path``; return the model, the history and metrics."""
    train = conf["train"]
    L.seed_everything(int(train["seed"]), workers=True, verbose=False)
    bins = check_encoding(conf["encoding"])
    data = TrajectoryData(train_path, val_path, bins, int(train["batch_size"]), int(train["seed"]),
                          bucket_by_length=bool(train.get("bucket_by_length", True)),
                          state_targets=float(train.get("state_loss_weight", 0.0)) > 0)
    data.setup()
    if len(data.train) == 0:
        raise InputError(train_path, "empty training set (dataset stage produced no training paths)")
    if len(data.val) == 0:
        raise InputError(val_path, "empty validation set (set dataset.val_fraction > 0)")
    model = build_model(conf, num_edges)
    history = History(every=max(1, int(train["log_every_n_steps"])))
    early_stopping = []
    if train.get("early_stopping_patience") is not None:
        early_stopping.append(L.pytorch.callbacks.EarlyStopping(monitor="val_loss", mode="min",
                                                                patience=int(train["early_stopping_patience"])))
    max_time = train.get("max_time_min")
    with best_checkpoint(model_path) as checkpoint:
        trainer = L.Trainer(
            accelerator=train["accelerator"],
            devices=1,
            max_epochs=int(train["max_epochs"]),
            max_time={"minutes": float(max_time)} if max_time is not None else None,
            logger=logger if logger is not None else False,
            callbacks=[history, checkpoint, *early_stopping],
            log_every_n_steps=int(train["log_every_n_steps"]),
            gradient_clip_val=train.get("gradient_clip"),
            enable_progress_bar=True,
            enable_model_summary=False,
            fast_dev_run=fast_dev_run,
            deterministic=True,
        )
        started = time.perf_counter()
        trainer.fit(model, datamodule=data)
        seconds = time.perf_counter() - started
        model = keep_best(checkpoint, trainer, model_path, model)
    frame = pd.DataFrame(history.rows, columns=["step", "epoch", "train_loss", "val_loss", "val_acc", "val_acc_last"])
    val_rows = frame.dropna(subset=["val_loss"])
    best_row = val_rows.loc[val_rows.val_loss.idxmin()] if len(val_rows) else None
    metrics = {
        "train_seconds": seconds,
        "epochs": float(trainer.current_epoch),
        "steps": float(trainer.global_step),
        "train_size": float(len(data.train)),
        "val_size": float(len(data.val)),
        "parameters": float(sum(p.numel() for p in model.parameters())),
    }
    if best_row is not None:
        metrics |= {"best_val_loss": float(best_row.val_loss), "best_val_acc_last": float(best_row.val_acc_last),
                    "best_epoch": float(best_row.epoch)}
    return model, frame, metrics


def log_mlflow_model(model: TrajectoryRNN) -> None:
    """Log ``model`` to the active MLflow run as a PyTorch model with an input/output signature."""
    import mlflow
    from mlflow.models import ModelSignature
    from mlflow.types import Schema, TensorSpec

    model = model.to("cpu").eval()
    bins = model.hparams.bins
    example = np.array([[bins // 2] * 6, [bins // 2, bins // 2, 3, bins // 2, bins // 2, bins // 2]], dtype=np.int64)
    with torch.no_grad():
        logits = model(torch.as_tensor(example)).numpy()
    # batch and sequence length are free: (-1, -1) int64 tokens -> (-1, -1, num_edges) float32 logits
    signature = ModelSignature(
        inputs=Schema([TensorSpec(np.dtype(np.int64), (-1, -1))]),
        outputs=Schema([TensorSpec(np.dtype(np.float32), (-1, -1, logits.shape[-1]))]),
    )
    mlflow.pytorch.log_model(model, name="model", signature=signature, input_example=example)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train on ``inputs`` train/val/stats; write ``model``, ``history`` and ``metrics``."""
    import mlflow
    from lightning.pytorch.loggers import MLFlowLogger

    stats = json.loads(Path(inputs["stats"]).read_text())
    active = mlflow.active_run()
    logger = MLFlowLogger(tracking_uri=tracking_uri(), run_id=active.info.run_id) if active else None
    model, history, metrics = fit(conf, inputs["train"], inputs["val"], int(stats["classes"]), outputs["model"], logger)
    with atomic_path(outputs["history"]) as tmp:
        history.to_csv(tmp, index=False)
    write_json(outputs["metrics"], metrics)
    log.info("trained: %s", metrics)
    if active and conf["train"].get("log_model", True):
        log_mlflow_model(model)
    return metrics
