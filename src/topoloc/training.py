"""Lightning helpers shared by the training stages: the loss history, and the best checkpoint written to the
stage's output only once training has finished."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import lightning as L

from topoloc.io import atomic_path


class History(L.Callback):
    """Training loss every ``every`` steps and the ``val_*`` metrics of every epoch, as rows for a table."""

    def __init__(self, every: int = 10) -> None:
        self.every = every
        self.rows: list[dict[str, float]] = []

    def on_train_batch_end(self, trainer: L.Trainer, module: L.LightningModule, outputs: Any, batch: Any,
                           batch_idx: int) -> None:
        if trainer.global_step % self.every == 0 and outputs is not None:
            loss = outputs["loss"] if isinstance(outputs, dict) else outputs
            self.rows.append({"step": trainer.global_step, "epoch": trainer.current_epoch, "train_loss": float(loss)})

    def on_validation_epoch_end(self, trainer: L.Trainer, module: L.LightningModule) -> None:
        if trainer.sanity_checking:
            return
        row = {"step": trainer.global_step, "epoch": trainer.current_epoch}
        row |= {k: float(v) for k, v in trainer.callback_metrics.items() if k.startswith("val_")}
        self.rows.append(row)


@contextmanager
def best_checkpoint(model_path: str | Path) -> Iterator[L.pytorch.callbacks.ModelCheckpoint]:
    """A callback keeping the checkpoint of lowest ``val_loss`` in a temporary folder beside ``model_path``.

    The folder is removed when the block ends, however it ends.
    """
    Path(model_path).parent.mkdir(parents=True, exist_ok=True)
    ckpt_dir = Path(tempfile.mkdtemp(prefix=".checkpoints-", dir=Path(model_path).parent))
    try:
        yield L.pytorch.callbacks.ModelCheckpoint(dirpath=ckpt_dir, filename="best", monitor="val_loss", mode="min",
                                                  save_top_k=1)
    finally:
        shutil.rmtree(ckpt_dir, ignore_errors=True)


def keep_best(checkpoint: L.pytorch.callbacks.ModelCheckpoint, trainer: L.Trainer, model_path: str | Path,
              model: L.LightningModule) -> L.LightningModule:
    """Copy the best checkpoint to ``model_path`` atomically and return it loaded on the CPU.

    Without one (``fast_dev_run`` saves none) the trainer's final state is written and ``model`` returned.
    """
    best = checkpoint.best_model_path
    with atomic_path(model_path) as tmp:
        if not best:
            trainer.save_checkpoint(tmp)
            return model
        shutil.copyfile(best, tmp)
    return type(model).load_from_checkpoint(best, map_location="cpu")
