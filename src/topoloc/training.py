"""The one training path of the Lightning stages (``train_rnn``, ``train_retrieval``).

:func:`fit` seeds, builds the LightningModule, runs the Trainer on a LightningDataModule with the loss
:class:`History` and a checkpoint of the lowest ``val/loss``, logs to the active MLflow run (the stage's run,
opened by :mod:`topoloc.stage`) through Lightning's MLFlowLogger, writes the best checkpoint to the stage's
output, restores it, and logs it to MLflow as a PyTorch model with its signature.

Metric names follow Lightning's style: ``train/loss``, ``val/loss``, ``val/acc``, ... (logged by the modules).
A fit's summary metrics are ``train_seconds``, ``epochs``, ``steps``, ``parameters``, ``time_capped`` and those
of the kept checkpoint: ``best/epoch`` and ``best/<metric>`` for each validation metric at that epoch
(``best/val/loss``, ...).

Reproducibility: a fit is bounded by ``max_epochs`` (and early stopping on ``val/loss``), never by the clock, so
the same config and seed give the same model on a quiet or a busy machine, only later on the busy one.
``max_time_min`` is a safety cap only: when it stops a fit, ``time_capped`` is 1 and a warning names the epochs
done, since the model then depends on the machine's speed.
"""

from __future__ import annotations

import logging
import shutil
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar

import lightning as L
import numpy as np
import pandas as pd
import torch

from topoloc.io import atomic_path, temporary_dir
from topoloc.tracking import tracking_uri

#: The metric that picks the checkpoint (and drives early stopping).
MONITOR = "val/loss"
#: What loading a logged model imports (the module's class is topoloc's, pickled): its requirements, pinned to the
#: installed versions. Named here because MLflow's own inference loads the model again in a subprocess (about 15 s
#: per model on a 2-core machine), and found these.
MODEL_DISTRIBUTIONS = ("torch", "lightning", "numpy", "pandas", "scipy", "matplotlib", "cloudpickle")
TRAIN_LOSS = "train/loss"
VAL_PREFIX = "val/"

Module = TypeVar("Module", bound=L.LightningModule)

log = logging.getLogger(__name__)


class History(L.Callback):
    """Training loss every ``every`` steps and the ``val/*`` metrics of every epoch, as rows for a table."""

    def __init__(self, every: int) -> None:
        self.every = every
        self.rows: list[dict[str, float]] = []

    def on_train_batch_end(self, trainer: L.Trainer, module: L.LightningModule, outputs: Any, batch: Any,
                           batch_idx: int) -> None:
        if trainer.global_step % self.every == 0 and outputs is not None:
            loss = outputs["loss"] if isinstance(outputs, dict) else outputs
            self.rows.append({"step": trainer.global_step, "epoch": trainer.current_epoch, TRAIN_LOSS: float(loss)})

    def on_validation_epoch_end(self, trainer: L.Trainer, module: L.LightningModule) -> None:
        if trainer.sanity_checking:
            return
        row = {"step": trainer.global_step, "epoch": trainer.current_epoch}
        row |= {k: float(v) for k, v in trainer.callback_metrics.items() if k.startswith(VAL_PREFIX)}
        self.rows.append(row)

    def frame(self) -> pd.DataFrame:
        """The rows as a table: ``step``, ``epoch``, ``train/loss``, ``val/loss``, then the other metrics."""
        columns = ["step", "epoch", TRAIN_LOSS, MONITOR]
        columns += list(dict.fromkeys(k for row in self.rows for k in row if k not in columns))
        return pd.DataFrame(self.rows, columns=columns)


@dataclass(frozen=True)
class FitSettings:
    """Trainer settings of one fit (from the stage's ``train`` config section)."""

    seed: int
    max_epochs: int
    max_time_min: float | None
    accelerator: str
    log_every_n_steps: int
    gradient_clip: float | None
    early_stopping_patience: int | None
    sanity_val_steps: int
    fast_dev_run: bool

    @classmethod
    def from_config(cls, train: Mapping[str, Any], *, gradient_clip: float | None,
                    early_stopping_patience: int | None, sanity_val_steps: int, fast_dev_run: bool) -> FitSettings:
        """The keys both trainings share (``seed``, ``max_epochs``, ``max_time_min``, ``accelerator``,
        ``log_every_n_steps``) from ``train``; the others as given."""
        max_time = train["max_time_min"]
        return cls(seed=int(train["seed"]), max_epochs=int(train["max_epochs"]),
                   max_time_min=float(max_time) if max_time is not None else None,
                   accelerator=str(train["accelerator"]), log_every_n_steps=int(train["log_every_n_steps"]),
                   gradient_clip=gradient_clip, early_stopping_patience=early_stopping_patience,
                   sanity_val_steps=int(sanity_val_steps), fast_dev_run=bool(fast_dev_run))


@dataclass(frozen=True)
class LoggedModel:
    """How the trained module is logged to MLflow: an input example, and how many leading axes are free
    (1: the batch; 2: batch and sequence length). The signature is read off the module's output for it."""

    example: np.ndarray
    free_axes: int


@dataclass(frozen=True)
class FitResult(Generic[Module]):
    """The restored best module (on the CPU), the :class:`History` table and the summary metrics."""

    module: Module
    history: pd.DataFrame
    metrics: dict[str, float]


def fit(build: Callable[[], Module], data: L.LightningDataModule, settings: FitSettings, model_path: str | Path, *,
        callbacks: Sequence[L.Callback] = (), logged_model: LoggedModel | None = None) -> FitResult[Module]:
    """Train the module of ``build`` on ``data``; write the best checkpoint to ``model_path`` and return it.

    ``build`` runs right after seeding, so the initial weights come from ``settings.seed``. Inside an active
    MLflow run the metrics go to that run, and with ``logged_model`` the best module is logged as a model.
    """
    L.seed_everything(settings.seed, workers=True, verbose=False)
    module = build()
    history = History(every=max(1, settings.log_every_n_steps))
    extra = list(callbacks)
    if settings.early_stopping_patience is not None:
        extra.append(L.pytorch.callbacks.EarlyStopping(monitor=MONITOR, mode="min",
                                                       patience=int(settings.early_stopping_patience)))
    run_logger = mlflow_logger()
    with best_checkpoint(model_path) as checkpoint:
        trainer = L.Trainer(
            accelerator=settings.accelerator,
            devices=1,
            max_epochs=settings.max_epochs,
            max_time={"minutes": settings.max_time_min} if settings.max_time_min is not None else None,
            logger=run_logger if run_logger is not None else False,
            callbacks=[history, checkpoint, *extra],
            log_every_n_steps=settings.log_every_n_steps,
            gradient_clip_val=settings.gradient_clip,
            num_sanity_val_steps=settings.sanity_val_steps,
            enable_progress_bar=True,
            enable_model_summary=False,
            fast_dev_run=settings.fast_dev_run,
            deterministic=True,
        )
        started = time.perf_counter()
        trainer.fit(module, datamodule=data)
        seconds = time.perf_counter() - started
        capped = time_capped(trainer)
        module = keep_best(checkpoint, trainer, model_path, module)
    if capped:
        log.warning("training stopped by the safety cap max_time_min=%s after %d of max_epochs=%d epochs (%d steps): "
                    "the model depends on the machine's speed; raise max_time_min or lower max_epochs",
                    settings.max_time_min, trainer.current_epoch, settings.max_epochs, trainer.global_step)
    frame = history.frame()
    metrics = {"train_seconds": seconds, "epochs": float(trainer.current_epoch), "steps": float(trainer.global_step),
               "parameters": float(sum(p.numel() for p in module.parameters())), "time_capped": float(capped)}
    metrics |= best_metrics(frame)
    if run_logger is not None and logged_model is not None:
        log_model(module, logged_model)
    return FitResult(module, frame, metrics)


def time_capped(trainer: L.Trainer) -> bool:
    """Whether the wall-clock cap (Lightning's :class:`~lightning.pytorch.callbacks.Timer`) stopped the fit."""
    for callback in trainer.callbacks:
        if isinstance(callback, L.pytorch.callbacks.Timer):
            remaining = callback.time_remaining()
            return remaining is not None and remaining <= 0
    return False


def best_metrics(history: pd.DataFrame) -> dict[str, float]:
    """``best/epoch`` and ``best/<metric>`` of the validation row of lowest ``val/loss`` (none without one)."""
    rows = history.dropna(subset=[MONITOR])
    if not len(rows):
        return {}
    best = rows.loc[rows[MONITOR].idxmin()]
    out = {f"best/{k}": float(best[k]) for k in rows.columns if k.startswith(VAL_PREFIX) and pd.notna(best[k])}
    return {"best/epoch": float(best.epoch), **out}


def mlflow_logger() -> Any:
    """Lightning's MLFlowLogger bound to the active MLflow run, or None outside one (without importing MLflow when
    nothing has: then no run can be active, and a training outside the pipeline needs no MLflow)."""
    if "mlflow" not in sys.modules:
        return None
    import mlflow
    from lightning.pytorch.loggers import MLFlowLogger

    active = mlflow.active_run()
    return MLFlowLogger(tracking_uri=tracking_uri(), run_id=active.info.run_id) if active else None


def log_model(module: L.LightningModule, logged: LoggedModel) -> None:
    """Log ``module`` to the active MLflow run as a PyTorch model with an input/output tensor signature."""
    import mlflow
    from mlflow.models import ModelSignature
    from mlflow.types import Schema, TensorSpec

    module = module.to("cpu").eval()
    with torch.no_grad():
        output = module(torch.as_tensor(logged.example)).numpy()
    free = (-1,) * logged.free_axes
    signature = ModelSignature(
        inputs=Schema([TensorSpec(logged.example.dtype, free + logged.example.shape[logged.free_axes:])]),
        outputs=Schema([TensorSpec(output.dtype, free + output.shape[logged.free_axes:])]),
    )
    mlflow.pytorch.log_model(module, name="model", signature=signature, input_example=logged.example,
                             pip_requirements=model_requirements())


def model_requirements() -> list[str]:
    """The pinned pip requirements of a logged model: :data:`MODEL_DISTRIBUTIONS` at their installed versions
    (without a local label such as torch's ``+cpu``, as MLflow writes them)."""
    from importlib.metadata import PackageNotFoundError, version

    pins = []
    for dist in MODEL_DISTRIBUTIONS:
        try:
            pins.append(f"{dist}=={version(dist).split('+')[0]}")
        except PackageNotFoundError:
            continue
    return pins


@contextmanager
def best_checkpoint(model_path: str | Path) -> Iterator[L.pytorch.callbacks.ModelCheckpoint]:
    """A callback keeping the checkpoint of lowest ``val/loss`` in a temporary folder beside ``model_path``.

    The folder is removed when the block ends, however it ends.
    """
    with temporary_dir(model_path) as ckpt_dir:  # .topoloc-tmp.<model name>.*, see topoloc.io
        yield L.pytorch.callbacks.ModelCheckpoint(dirpath=ckpt_dir, filename="best", monitor=MONITOR, mode="min",
                                                  save_top_k=1)


def keep_best(checkpoint: L.pytorch.callbacks.ModelCheckpoint, trainer: L.Trainer, model_path: str | Path,
              module: Module) -> Module:
    """Copy the best checkpoint to ``model_path`` atomically and return it loaded on the CPU.

    Without one (``fast_dev_run`` saves none) the trainer's final state is written and ``module`` returned.
    """
    best = checkpoint.best_model_path
    with atomic_path(model_path) as tmp:
        if not best:
            trainer.save_checkpoint(tmp)
            return module
        shutil.copyfile(best, tmp)
    return type(module).load_from_checkpoint(best, map_location="cpu")
