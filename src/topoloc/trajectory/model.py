"""The trajectory RNN: angle-token embedding -> one recurrent layer -> edge-class logits per step.

Sequences are right-padded with the token ``bins`` (its own embedding row)
and the label ``IGNORE``. The network is unidirectional, so its outputs at
real steps never see the padding behind them: packing is not needed for
correctness, and the per-step cross-entropy ignores the padded steps.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import lightning as L
import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset

IGNORE = -100
CELLS = {"rnn": nn.RNN, "gru": nn.GRU, "lstm": nn.LSTM}


class TrajectoryRNN(L.LightningModule):
    """Embedding(bins + pad) -> RNN/GRU/LSTM -> Linear(num_edges)."""

    def __init__(
        self,
        bins: int,
        num_edges: int,
        cell: str = "gru",
        hidden_size: int = 128,
        embedding_dim: int = 32,
        optimizer: str = "adam",
        lr: float = 3e-3,
        weight_decay: float = 0.0,
        plateau_factor: float | None = None,
        plateau_patience: int = 1,
    ) -> None:
        super().__init__()
        if cell not in CELLS:
            raise ValueError(f"cell must be one of {sorted(CELLS)}, got {cell!r}")
        self.save_hyperparameters()
        self.embedding = nn.Embedding(bins + 1, embedding_dim, padding_idx=bins)
        self.rnn = CELLS[cell](embedding_dim, hidden_size, num_layers=1, batch_first=True)
        self.head = nn.Linear(hidden_size, num_edges)
        self.loss = nn.CrossEntropyLoss(ignore_index=IGNORE)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """Logits of shape ``(batch, steps, num_edges)`` for int tokens ``(batch, steps)``."""
        out, _ = self.rnn(self.embedding(tokens))
        return self.head(out)

    def _step(self, batch: tuple[torch.Tensor, torch.Tensor, torch.Tensor], stage: str) -> torch.Tensor:
        tokens, labels, lengths = batch
        logits = self(tokens)
        loss = self.loss(logits.reshape(-1, logits.shape[-1]), labels.reshape(-1))
        with torch.no_grad():
            pred = logits.argmax(-1)
            mask = labels != IGNORE
            acc = (pred[mask] == labels[mask]).float().mean()
            rows = torch.arange(len(lengths), device=tokens.device)
            last = (pred[rows, lengths - 1] == labels[rows, lengths - 1]).float().mean()
        on_step = stage == "train"
        self.log(f"{stage}_loss", loss, prog_bar=True, on_step=on_step, on_epoch=True, batch_size=len(lengths))
        self.log(f"{stage}_acc", acc, on_step=False, on_epoch=True, batch_size=len(lengths))
        self.log(f"{stage}_acc_last", last, prog_bar=stage == "val", on_step=False, on_epoch=True, batch_size=len(lengths))
        return loss

    def training_step(self, batch: Any, batch_idx: int) -> torch.Tensor:
        return self._step(batch, "train")

    def validation_step(self, batch: Any, batch_idx: int) -> torch.Tensor:
        return self._step(batch, "val")

    def configure_optimizers(self) -> Any:
        hp = self.hparams
        if hp.optimizer == "sgd":
            optimizer = torch.optim.SGD(self.parameters(), lr=hp.lr, weight_decay=hp.weight_decay)
        else:
            optimizer = torch.optim.Adam(self.parameters(), lr=hp.lr, weight_decay=hp.weight_decay)
        if not hp.get("plateau_factor"):
            return optimizer
        # multiply the learning rate by plateau_factor when the validation loss stops improving
        scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(optimizer, factor=hp.plateau_factor, patience=hp.plateau_patience)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "monitor": "val_loss", "interval": "epoch"}}


class Sequences(Dataset):
    """Token and label sequences (numpy int arrays) of one split."""

    def __init__(self, tokens: Sequence[np.ndarray], labels: Sequence[np.ndarray]) -> None:
        self.tokens = [torch.as_tensor(t, dtype=torch.long) for t in tokens]
        self.labels = [torch.as_tensor(lab, dtype=torch.long) for lab in labels]

    def __len__(self) -> int:
        return len(self.tokens)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self.tokens[index], self.labels[index]


def pad_batch(items: Sequence[tuple[torch.Tensor, torch.Tensor]], pad_token: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Right-pad a batch: tokens with ``pad_token``, labels with :data:`IGNORE`; plus the lengths."""
    tokens = nn.utils.rnn.pad_sequence([t for t, _ in items], batch_first=True, padding_value=pad_token)
    labels = nn.utils.rnn.pad_sequence([lab for _, lab in items], batch_first=True, padding_value=IGNORE)
    lengths = torch.tensor([len(t) for t, _ in items], dtype=torch.long)
    return tokens, labels, lengths


class TrajectoryData(L.LightningDataModule):
    """Train and validation sequences from the dataset stage's Parquet files."""

    def __init__(self, train_path: str, val_path: str, bins: int, batch_size: int, seed: int = 0, num_workers: int = 0) -> None:
        super().__init__()
        self.train_path, self.val_path = train_path, val_path
        self.bins, self.batch_size, self.seed, self.num_workers = bins, batch_size, seed, num_workers
        self.train: Sequences | None = None
        self.val: Sequences | None = None

    def setup(self, stage: str | None = None) -> None:
        from topoloc.trajectory.dataset import load_sequences

        if self.train is None:
            self.train = Sequences(*load_sequences(self.train_path))
            self.val = Sequences(*load_sequences(self.val_path))

    def _loader(self, data: Sequences, shuffle: bool, batch_size: int) -> DataLoader:
        generator = torch.Generator().manual_seed(self.seed)
        return DataLoader(data, batch_size=batch_size, shuffle=shuffle, generator=generator,
                          collate_fn=lambda items: pad_batch(items, self.bins), num_workers=self.num_workers)

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.train, True, self.batch_size)

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.val, False, max(self.batch_size, 256))


@torch.no_grad()
def predict(model: TrajectoryRNN, tokens: Sequence[np.ndarray], batch_size: int = 512) -> list[np.ndarray]:
    """Predicted edge id at every step of every sequence."""
    model.eval()
    bins = model.hparams.bins
    out: list[np.ndarray] = []
    order = np.argsort([len(t) for t in tokens], kind="stable")  # similar lengths per batch: less padding
    preds: dict[int, np.ndarray] = {}
    for start in range(0, len(order), batch_size):
        idx = order[start:start + batch_size]
        batch = nn.utils.rnn.pad_sequence([torch.as_tensor(tokens[i], dtype=torch.long) for i in idx], batch_first=True, padding_value=bins)
        arg = model(batch.to(model.device)).argmax(-1).cpu().numpy()
        for row, i in enumerate(idx):
            preds[int(i)] = arg[row, : len(tokens[i])]
    out = [preds[i] for i in range(len(tokens))]
    return out
