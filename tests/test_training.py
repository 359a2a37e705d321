"""The shared Lightning fit: the best checkpoint is kept and restored, seeds repeat, MLflow gets the metrics and model."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, TensorDataset

from topoloc import tracking
from topoloc.training import FitSettings, LoggedModel, fit

#: Scripted validation losses per epoch: in the first three, the best epoch (1) is neither the first nor the last.
VAL_LOSSES = [3.0, 1.0, 2.0, 0.5]


class Line(L.LightningModule):
    """y = w x + b fitted by SGD; its validation loss follows :data:`VAL_LOSSES`."""

    def __init__(self) -> None:
        super().__init__()
        self.layer = torch.nn.Linear(3, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.layer(x)

    def training_step(self, batch, batch_idx):
        x, y = batch
        loss = torch.nn.functional.mse_loss(self(x), y)
        self.log("train/loss", loss)
        return loss

    def validation_step(self, batch, batch_idx):
        self.log("val/loss", VAL_LOSSES[self.current_epoch] + 0.0 * self.layer.weight.sum())
        self.log("val/acc", 1.0 / VAL_LOSSES[self.current_epoch])

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.05)


class Points(L.LightningDataModule):
    def __init__(self) -> None:
        super().__init__()
        x = torch.randn(32, 3, generator=torch.Generator().manual_seed(1))
        self.data = TensorDataset(x, x @ torch.tensor([[1.0], [-2.0], [0.5]]) + 0.3)

    def train_dataloader(self) -> DataLoader:
        return DataLoader(self.data, batch_size=4, shuffle=True, generator=torch.Generator().manual_seed(2))

    def val_dataloader(self) -> DataLoader:
        return DataLoader(self.data, batch_size=16)


class Snapshots(L.Callback):
    """The weights at the end of every validation."""

    def __init__(self) -> None:
        self.weights: list[torch.Tensor] = []

    def on_validation_end(self, trainer: L.Trainer, module: L.LightningModule) -> None:
        self.weights.append(module.layer.weight.detach().clone())


def settings(**changes) -> FitSettings:
    base = {"seed": 0, "max_epochs": 3, "max_time_min": None, "accelerator": "cpu", "log_every_n_steps": 2,
            "gradient_clip": None, "early_stopping_patience": None, "sanity_val_steps": 0, "fast_dev_run": False}
    return FitSettings(**(base | changes))


def test_fit_restores_the_best_checkpoint_and_repeats_with_its_seed(tmp_path):
    snapshots = Snapshots()
    result = fit(Line, Points(), settings(), tmp_path / "model.ckpt", callbacks=[snapshots])
    assert len(snapshots.weights) == 3 and not torch.equal(snapshots.weights[1], snapshots.weights[2])
    assert torch.equal(result.module.layer.weight, snapshots.weights[1])
    assert torch.load(tmp_path / "model.ckpt", weights_only=False)["epoch"] == 1
    assert not list(tmp_path.glob(".topoloc-tmp.*"))  # the temporary checkpoints are gone
    history = result.history
    assert list(history.columns) == ["step", "epoch", "train/loss", "val/loss", "val/acc"]
    assert history["val/loss"].dropna().tolist() == VAL_LOSSES[:3] and history["train/loss"].notna().sum() == 12
    assert result.metrics["best/epoch"] == 1 and result.metrics["best/val/loss"] == 1.0
    assert result.metrics["best/val/acc"] == 1.0 and result.metrics["steps"] == 24
    again = fit(Line, Points(), settings(), tmp_path / "again.ckpt")
    assert torch.equal(again.module.layer.weight, result.module.layer.weight)
    assert again.history["train/loss"].dropna().tolist() == history["train/loss"].dropna().tolist()
    other = fit(Line, Points(), settings(seed=1), tmp_path / "other.ckpt")
    assert not torch.equal(other.module.layer.weight, result.module.layer.weight)


def test_early_stopping_watches_val_loss(tmp_path):
    result = fit(Line, Points(), settings(max_epochs=4), tmp_path / "model.ckpt")
    assert result.metrics["best/epoch"] == 3 and result.metrics["best/val/loss"] == 0.5
    result = fit(Line, Points(), settings(max_epochs=4, early_stopping_patience=0), tmp_path / "model.ckpt")
    assert result.history["val/loss"].dropna().tolist() == VAL_LOSSES[:3]  # epoch 2 is worse than 1: stop after it
    assert result.metrics["best/epoch"] == 1


def test_fit_logs_metrics_and_model_to_the_stage_run(tmp_path, monkeypatch):
    import mlflow
    from mlflow import MlflowClient

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    example = np.zeros((2, 3), np.float32)
    with tracking.StageRun("exp", "train_line", {}, {"train": {"lr": 0.05}}) as run:
        result = fit(Line, Points(), settings(), tmp_path / "model.ckpt", logged_model=LoggedModel(example, 1))
        run.log_metrics(result.metrics)
    client = MlflowClient(tracking.default_tracking_uri())
    logged = client.get_run(run.run_id)
    assert {"train/loss", "val/loss", "val/acc", "best/val/loss", "best/epoch", "epoch"} <= set(logged.data.metrics)
    assert [m.value for m in client.get_metric_history(run.run_id, "val/loss")] == VAL_LOSSES[:3]
    assert logged.data.params["train.lr"] == "0.05"
    mlflow.set_tracking_uri(tracking.default_tracking_uri())
    try:
        models = mlflow.search_logged_models(experiment_ids=[logged.info.experiment_id], output_format="list")
        assert [m.source_run_id for m in models] == [run.run_id]
        signature = mlflow.models.get_model_info(f"models:/{models[0].model_id}").signature
        requirements = Path(mlflow.pyfunc.get_model_dependencies(f"models:/{models[0].model_id}")).read_text().split()
        loaded = mlflow.pytorch.load_model(f"models:/{models[0].model_id}")
    finally:
        mlflow.set_tracking_uri(None)
    assert signature.inputs.inputs[0].shape == (-1, 3) and signature.outputs.inputs[0].shape == (-1, 1)
    # pinned to what is installed (named, not inferred by loading the model again), and it loads
    assert f"torch=={torch.__version__.split('+')[0]}" in requirements
    assert {r.split("==")[0] for r in requirements} >= {"torch", "lightning", "numpy"}
    assert torch.allclose(loaded(torch.as_tensor(example)), result.module(torch.as_tensor(example)))


def test_fast_dev_run_writes_the_last_state(tmp_path):
    result = fit(Line, Points(), settings(fast_dev_run=True), tmp_path / "model.ckpt")
    assert (tmp_path / "model.ckpt").is_file() and result.metrics["steps"] == 1


class Shuffled(Line):
    """A small MLP on shuffled batches with dropout: every source of randomness a real training has."""

    def __init__(self) -> None:
        super().__init__()
        self.layer = torch.nn.Sequential(torch.nn.Linear(3, 16), torch.nn.ReLU(), torch.nn.Dropout(0.2),
                                         torch.nn.Linear(16, 1))

    def validation_step(self, batch, batch_idx):
        x, y = batch
        self.log("val/loss", torch.nn.functional.mse_loss(self(x), y))

    def configure_optimizers(self):
        return torch.optim.Adam(self.parameters(), lr=0.01)


class Slow(L.Callback):
    """A busy machine: every training step takes ``seconds`` longer."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def on_train_batch_end(self, *args) -> None:
        import time

        time.sleep(self.seconds)


def _comparable(metrics: dict[str, float]) -> dict[str, float]:
    return {k: v for k, v in metrics.items() if k != "train_seconds"}


def test_same_config_and_seed_give_the_same_metrics_on_a_slower_machine(tmp_path):
    quiet = fit(Shuffled, Points(), settings(max_epochs=3, max_time_min=5.0), tmp_path / "quiet.ckpt")
    busy = fit(Shuffled, Points(), settings(max_epochs=3, max_time_min=5.0), tmp_path / "busy.ckpt",
               callbacks=[Slow(0.02)])
    assert quiet.metrics["time_capped"] == 0 and quiet.metrics["steps"] == 24
    assert busy.metrics["train_seconds"] > quiet.metrics["train_seconds"]
    assert _comparable(busy.metrics) == _comparable(quiet.metrics)
    assert busy.history.equals(quiet.history)
    for a, b in zip(busy.module.parameters(), quiet.module.parameters(), strict=True):
        assert torch.equal(a, b)


def test_the_wall_clock_cap_is_reported_when_it_stops_a_fit(tmp_path, caplog):
    with caplog.at_level("WARNING", logger="topoloc.training"):
        result = fit(Shuffled, Points(), settings(max_epochs=50, max_time_min=0.01), tmp_path / "capped.ckpt",
                     callbacks=[Slow(0.1)])
    assert result.metrics["time_capped"] == 1 and result.metrics["epochs"] < 50
    assert "safety cap max_time_min=0.01" in caplog.text
