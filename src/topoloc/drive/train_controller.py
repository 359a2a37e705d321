"""Stage ``train_controller``: fit Topo-DLM (:mod:`topoloc.drive.controller`) on the expert's demonstrations.

Data: the demonstrations of ``simulate_demonstrations``; the last ``demonstrations.val_routes`` routes are
for validation (``val/loss``, ``val/steer_mae`` pick the checkpoint), the others for training. Every epoch draws
``train.batches_per_epoch`` batches of ``train.batch_size`` steps with the commands balanced (each command
present in the data is drawn equally often: turns are rare), seeded by ``train.seed``.

Trained by :func:`topoloc.training.fit` (the shared Lightning path): the best checkpoint is written to
``model`` and logged to MLflow as a PyTorch model with its signature (``(N, C + 2, H, W)`` -> ``(N, 2)``).
"""

from __future__ import annotations

import logging
from typing import Any

import lightning as L
import numpy as np
import pandas as pd
import torch
from torch.utils.data import DataLoader, TensorDataset, WeightedRandomSampler

from topoloc.drive.controller import TopoDLM
from topoloc.drive.demonstrations import Demonstrations
from topoloc.drive.plot import training_figure
from topoloc.errors import InputError
from topoloc.io import atomic_path, write_json
from topoloc.place.topometric_map import COMMANDS
from topoloc.training import FitSettings, LoggedModel
from topoloc.training import fit as fit_module

log = logging.getLogger(__name__)


def _tensors(demos: Demonstrations, idx: np.ndarray, max_speed: float) -> TensorDataset:
    target = np.column_stack([demos.steer[idx], demos.target_speed[idx] / max_speed]).astype(np.float32)
    return TensorDataset(torch.from_numpy(np.ascontiguousarray(demos.images[idx])), torch.from_numpy(demos.speed[idx]),
                         torch.from_numpy(demos.command[idx]), torch.from_numpy(target))


class DemoData(L.LightningDataModule):
    """Command-balanced training batches and the validation routes' steps in order."""

    def __init__(self, demos: Demonstrations, val_routes: int, train: dict[str, Any], max_speed: float) -> None:
        super().__init__()
        routes = np.unique(demos.route)
        if len(routes) <= val_routes:
            raise InputError("drive.demonstrations.val_routes", f"the demonstrations hold {len(routes)} routes; "
                             f"{val_routes} for validation leaves none to train on")
        val = np.isin(demos.route, routes[len(routes) - val_routes:])
        self.train_idx, self.val_idx = np.flatnonzero(~val), np.flatnonzero(val)
        if not len(self.val_idx):
            raise InputError("drive.demonstrations.val_routes", "no validation step")
        self.demos, self.train_conf, self.max_speed = demos, train, max_speed
        counts = np.bincount(demos.command[self.train_idx], minlength=len(COMMANDS)).astype(float)
        self.weights = 1.0 / counts[demos.command[self.train_idx]]

    def train_dataloader(self) -> DataLoader:
        batch = int(self.train_conf["batch_size"])
        generator = torch.Generator().manual_seed(int(self.train_conf["seed"]))
        sampler = WeightedRandomSampler(self.weights.tolist(), batch * int(self.train_conf["batches_per_epoch"]),
                                        replacement=True, generator=generator)
        return DataLoader(_tensors(self.demos, self.train_idx, self.max_speed), batch_size=batch, sampler=sampler)

    def val_dataloader(self) -> DataLoader:
        return DataLoader(_tensors(self.demos, self.val_idx, self.max_speed), batch_size=256)


def build_model(drive: dict[str, Any], demos: Demonstrations) -> TopoDLM:
    """The controller of ``drive.network`` with the settings of ``drive.train`` for images shaped like ``demos``'."""
    net, train = drive["network"], drive["train"]
    h, w, c = demos.images.shape[1:]
    return TopoDLM(in_channels=c, height=h, width=w, channels=list(net["channels"]), hidden=int(net["hidden"]),
                   downsample=int(net["downsample"]),
                   dropout=float(net["dropout"]), max_speed=float(drive["vehicle"]["max_speed_mps"]),
                   speed_gain=float(drive["expert"]["speed_gain"]), lr=float(train["lr"]),
                   weight_decay=float(train["weight_decay"]), steer_weight=float(train["steer_weight"]),
                   speed_weight=float(train["speed_weight"]), augment=bool(train["augment"]), seed=int(train["seed"]))


def signature_example(demos: Demonstrations) -> np.ndarray:
    """Two steps as the logged model's input ``(2, C + 2, H, W)`` float32: image, speed plane, command plane."""
    images = demos.images[:2].astype(np.float32).transpose(0, 3, 1, 2)
    planes = np.ones((len(images), 2, *images.shape[2:]), np.float32)
    planes[:, 0] *= demos.speed[:2, None, None]
    planes[:, 1] *= demos.command[:2, None, None]
    return np.ascontiguousarray(np.concatenate([images, planes], axis=1))


def fit(drive: dict[str, Any], demos: Demonstrations, model_path: str, log_model: bool = False,
        fast_dev_run: bool = False) -> tuple[TopoDLM, pd.DataFrame, dict[str, float]]:
    """Train on ``demos``; write the best checkpoint to ``model_path``; return the model, history and metrics."""
    train = drive["train"]
    torch.set_num_threads(int(drive["threads"]))
    data = DemoData(demos, int(drive["demonstrations"]["val_routes"]), train, float(drive["vehicle"]["max_speed_mps"]))
    settings = FitSettings.from_config(train, gradient_clip=1.0, early_stopping_patience=None, sanity_val_steps=0,
                                       fast_dev_run=fast_dev_run)
    logged = LoggedModel(signature_example(demos), free_axes=1) if log_model else None
    result = fit_module(lambda: build_model(drive, demos), data, settings, model_path, logged_model=logged)
    metrics = result.metrics | {"train_steps": float(len(data.train_idx)), "val_steps": float(len(data.val_idx))}
    return result.module, result.history, metrics


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train on ``inputs['demonstrations']``; write ``model``, ``history``, ``metrics`` and ``figure``."""
    drive = conf["drive"]
    demos = Demonstrations.load(inputs["demonstrations"])
    _, history, metrics = fit(drive, demos, outputs["model"], log_model=bool(drive["train"]["log_model"]))
    with atomic_path(outputs["history"]) as tmp:
        history.to_csv(tmp, index=False)
    write_json(outputs["metrics"], metrics)
    training_figure(history, outputs["figure"])
    log.info("trained: %s", metrics)
    return metrics
