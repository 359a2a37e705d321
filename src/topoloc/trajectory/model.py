"""The trajectory RNN: angle-token embedding (+ continuous features) -> one recurrent layer -> edge logits per step.

With ``feature_dim`` > 0 each step's input is the token's embedding concatenated with its continuous
features (:func:`topoloc.segmentation.token_features`: distance since the last token, unquantized turning
angle, heading change), which keep the metric information the 20 angle bins round away.

With ``state_loss_weight`` > 0 a second linear head on the same recurrent
outputs is trained to predict the rest of the vehicle's position at each step
(travel direction on the edge, steps since entering it): auxiliary targets
that make the state the network must track explicit. They cost little
and generalise to unseen trajectories markedly better (docs/trajectory.md); the head is
not used for prediction.

Sequences are right-padded with the token ``bins`` (its own embedding row)
and the label ``IGNORE``. The network is unidirectional, so its outputs at
real steps never see the padding behind them: packing is not needed for
correctness, and the per-step cross-entropy ignores the padded steps.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset, Sampler

from topoloc.errors import InputError
from topoloc.tracking import tracking_uri as default_uri
from topoloc.trajectory.dataset import MAX_OFFSET, load_features, load_sequences, load_state_targets

IGNORE = -100
CHECKPOINT_ARTIFACT = "checkpoint"
CELLS = {"rnn": nn.RNN, "gru": nn.GRU, "lstm": nn.LSTM}
SCHEDULES = ("constant", "onecycle", "plateau")


class TrajectoryRNN(L.LightningModule):
    """Embedding(bins + pad) [+ feature_dim continuous inputs] -> RNN/GRU/LSTM -> Linear(num_edges)."""

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
        lr_schedule: str = "constant",
        plateau_factor: float = 0.3,
        plateau_patience: int = 1,
        warmup_fraction: float = 0.15,
        state_loss_weight: float = 0.0,
        feature_dim: int = 0,
    ) -> None:
        super().__init__()
        if cell not in CELLS:
            raise ValueError(f"cell must be one of {sorted(CELLS)}, got {cell!r}")
        if lr_schedule not in SCHEDULES:
            raise ValueError(f"lr_schedule must be one of {SCHEDULES}, got {lr_schedule!r}")
        self.save_hyperparameters()
        self.embedding = nn.Embedding(bins + 1, embedding_dim, padding_idx=bins)
        self.rnn = CELLS[cell](embedding_dim + feature_dim, hidden_size, num_layers=1, batch_first=True)
        self.head = nn.Linear(hidden_size, num_edges)
        if state_loss_weight > 0:
            # auxiliary heads (training only): travel direction and offset along the edge
            self.state_head = nn.Linear(hidden_size, 2 + MAX_OFFSET + 1)
        self.loss = nn.CrossEntropyLoss(ignore_index=IGNORE)

    def forward(self, tokens: torch.Tensor, inputs: torch.Tensor | None = None) -> torch.Tensor:
        """Logits of shape ``(batch, steps, num_edges)`` for int tokens ``(batch, steps)`` and, with
        ``feature_dim`` > 0, float features ``(batch, steps, feature_dim)`` (zeros when left out)."""
        return self.head(self.features(tokens, inputs))

    def step_input(self, tokens: torch.Tensor, inputs: torch.Tensor | None = None) -> torch.Tensor:
        """The recurrent layer's input: the token embedding, and the continuous features beside it."""
        embedded = self.embedding(tokens)
        dim = int(self.hparams.get("feature_dim", 0))
        if dim == 0:
            return embedded
        if inputs is None:
            inputs = torch.zeros(*tokens.shape, dim, dtype=embedded.dtype, device=embedded.device)
        return torch.cat([embedded, inputs.to(embedded.dtype)], dim=-1)

    def features(self, tokens: torch.Tensor, inputs: torch.Tensor | None = None) -> torch.Tensor:
        """The recurrent layer's outputs ``(batch, steps, hidden_size)``."""
        out, _ = self.rnn(self.step_input(tokens, inputs))
        return out

    def _step(self, batch: tuple[torch.Tensor, ...], stage: str) -> torch.Tensor:
        tokens, labels, lengths, inputs, *state = batch
        features = self.features(tokens, inputs)
        logits = self.head(features)
        loss = edge_loss = self.loss(logits.reshape(-1, logits.shape[-1]), labels.reshape(-1))
        if state and self.hparams.state_loss_weight > 0:
            directions, offsets = state
            aux = self.state_head(features)
            state_loss = (self.loss(aux[..., :2].reshape(-1, 2), directions.reshape(-1))
                          + self.loss(aux[..., 2:].reshape(-1, MAX_OFFSET + 1), offsets.reshape(-1)))
            loss = edge_loss + self.hparams.state_loss_weight * state_loss
            self.log(f"{stage}/state_loss", state_loss, on_step=False, on_epoch=True, batch_size=len(lengths))
        with torch.no_grad():
            pred = logits.argmax(-1)
            mask = labels != IGNORE
            acc = (pred[mask] == labels[mask]).float().mean()
            rows = torch.arange(len(lengths), device=tokens.device)
            last = (pred[rows, lengths - 1] == labels[rows, lengths - 1]).float().mean()
        on_step = stage == "train"
        # the edge cross-entropy: comparable with and without the auxiliary losses
        self.log(f"{stage}/loss", edge_loss, prog_bar=True, on_step=on_step, on_epoch=True, batch_size=len(lengths))
        self.log(f"{stage}/acc", acc, on_step=False, on_epoch=True, batch_size=len(lengths))
        self.log(f"{stage}/acc_last", last, prog_bar=stage == "val", on_step=False, on_epoch=True, batch_size=len(lengths))
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
        if hp.lr_schedule == "onecycle":
            # warm up to lr over warmup_fraction of the planned steps, then anneal to ~0 by the last epoch
            scheduler = torch.optim.lr_scheduler.OneCycleLR(
                optimizer, max_lr=hp.lr, total_steps=max(2, int(self.trainer.estimated_stepping_batches)),
                pct_start=hp.warmup_fraction)
            return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}
        if hp.lr_schedule == "plateau":
            # multiply the learning rate by plateau_factor when the validation loss stops improving
            scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(optimizer, factor=hp.plateau_factor, patience=hp.plateau_patience)
            return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "monitor": "val/loss", "interval": "epoch"}}
        return optimizer


class Sequences(Dataset):
    """Token and label sequences (numpy int arrays) of one split, their continuous features ``(T, F)`` (F may
    be 0), optionally with per-step state targets."""

    def __init__(self, tokens: Sequence[np.ndarray], labels: Sequence[np.ndarray], inputs: Sequence[np.ndarray],
                 *targets: Sequence[np.ndarray]) -> None:
        self.tokens = [torch.as_tensor(t, dtype=torch.long) for t in tokens]
        self.columns = ([self.tokens, [torch.as_tensor(x, dtype=torch.long) for x in labels],
                         [torch.as_tensor(x, dtype=torch.float32) for x in inputs]]
                        + [[torch.as_tensor(x, dtype=torch.long) for x in column] for column in targets])

    def __len__(self) -> int:
        return len(self.tokens)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, ...]:
        return tuple(column[index] for column in self.columns)


class LengthBucketBatches(Sampler[list[int]]):
    """Shuffled batches of similar-length sequences (less padding, same data per epoch).

    Each pass draws a random order from ``generator``, sorts each window of
    ``window_batches`` batches by length, cuts it into batches and shuffles
    the batches: the composition is random but a batch wastes little compute
    on padding.
    """

    def __init__(self, lengths: Sequence[int], batch_size: int, generator: torch.Generator, window_batches: int = 50) -> None:
        self.lengths = torch.as_tensor(list(lengths))
        self.batch_size, self.generator, self.window = batch_size, generator, batch_size * window_batches

    def __len__(self) -> int:
        return (len(self.lengths) + self.batch_size - 1) // self.batch_size

    def __iter__(self) -> Iterator[list[int]]:
        order = torch.randperm(len(self.lengths), generator=self.generator)
        batches: list[list[int]] = []
        for start in range(0, len(order), self.window):
            window = order[start:start + self.window]
            window = window[torch.argsort(self.lengths[window], stable=True)].tolist()
            batches += [window[i:i + self.batch_size] for i in range(0, len(window), self.batch_size)]
        for index in torch.randperm(len(batches), generator=self.generator).tolist():
            yield batches[index]


def pad_batch(items: Sequence[tuple[torch.Tensor, ...]], pad_token: int) -> tuple[torch.Tensor, ...]:
    """Right-pad a batch of ``(tokens, labels, features, *targets)``: tokens with ``pad_token``, features with
    0, labels (and targets) with :data:`IGNORE`; plus the lengths.

    Returns ``(tokens, labels, lengths, features, *targets)``.
    """
    columns = list(zip(*items))
    tokens = nn.utils.rnn.pad_sequence(list(columns[0]), batch_first=True, padding_value=pad_token)
    labels = nn.utils.rnn.pad_sequence(list(columns[1]), batch_first=True, padding_value=IGNORE)
    inputs = nn.utils.rnn.pad_sequence(list(columns[2]), batch_first=True, padding_value=0.0)
    rest = [nn.utils.rnn.pad_sequence(list(column), batch_first=True, padding_value=IGNORE) for column in columns[3:]]
    lengths = torch.tensor([len(t) for t in columns[0]], dtype=torch.long)
    return tokens, labels, lengths, inputs, *rest


class TrajectoryData(L.LightningDataModule):
    """Train and validation sequences from the dataset stage's Parquet files."""

    def __init__(self, train_path: str, val_path: str, bins: int, batch_size: int, seed: int = 0,
                 bucket_by_length: bool = True, state_targets: bool = False, num_workers: int = 0,
                 feature_dim: int = 0) -> None:
        super().__init__()
        self.feature_dim = feature_dim
        self.train_path, self.val_path, self.bucket_by_length = train_path, val_path, bucket_by_length
        self.state_targets = state_targets
        self.bins, self.batch_size, self.seed, self.num_workers = bins, batch_size, seed, num_workers
        self.train: Sequences | None = None
        self.val: Sequences | None = None

    def setup(self, stage: str | None = None) -> None:
        if self.train is None:
            extra = (lambda path: load_state_targets(path)) if self.state_targets else (lambda path: ())
            self.train = self._load(self.train_path, extra)
            self.val = self._load(self.val_path, extra)

    def _load(self, path: str, extra: Any) -> Sequences:
        tokens, labels = load_sequences(path)
        inputs = (load_features(path, self.feature_dim) if self.feature_dim
                  else [np.zeros((len(t), 0), np.float32) for t in tokens])
        return Sequences(tokens, labels, inputs, *extra(path))

    def _collate(self, items: Sequence[tuple[torch.Tensor, ...]]) -> tuple[torch.Tensor, ...]:
        return pad_batch(items, self.bins)

    def train_dataloader(self) -> DataLoader:
        generator = torch.Generator().manual_seed(self.seed)
        if self.bucket_by_length:
            sampler = LengthBucketBatches([len(t) for t in self.train.tokens], self.batch_size, generator)
            return DataLoader(self.train, batch_sampler=sampler, collate_fn=self._collate, num_workers=self.num_workers)
        return DataLoader(self.train, batch_size=self.batch_size, shuffle=True, generator=generator,
                          collate_fn=self._collate, num_workers=self.num_workers)

    def val_dataloader(self) -> DataLoader:
        return DataLoader(self.val, batch_size=max(self.batch_size, 256), shuffle=False, collate_fn=self._collate,
                          num_workers=self.num_workers)


@torch.no_grad()
def predict(model: TrajectoryRNN, tokens: Sequence[np.ndarray], batch_size: int = 512,
            inputs: Sequence[np.ndarray] | None = None) -> list[np.ndarray]:
    """Predicted edge id at every step of every sequence (``inputs``: their features, for a model with some)."""
    model.eval()
    bins = model.hparams.bins
    out: list[np.ndarray] = []
    order = np.argsort([len(t) for t in tokens], kind="stable")  # similar lengths per batch: less padding
    preds: dict[int, np.ndarray] = {}
    for start in range(0, len(order), batch_size):
        idx = order[start:start + batch_size]
        batch = nn.utils.rnn.pad_sequence([torch.as_tensor(tokens[i], dtype=torch.long) for i in idx], batch_first=True, padding_value=bins)
        feats = None if inputs is None else nn.utils.rnn.pad_sequence(
            [torch.as_tensor(inputs[i], dtype=torch.float32) for i in idx], batch_first=True).to(model.device)
        arg = model(batch.to(model.device), feats).argmax(-1).cpu().numpy()
        for row, i in enumerate(idx):
            preds[int(i)] = arg[row, : len(tokens[i])]
    out = [preds[i] for i in range(len(tokens))]
    return out


def load_model(spec: str, tracking_uri: str | None = None) -> Any:
    """The trajectory RNN from a ``.ckpt`` path, an MLflow model URI (``runs:/<id>/model``) or a bare run id.

    An unknown file, run id or URI raises :class:`InputError` naming it.
    """
    path = Path(spec)
    if path.suffix == ".ckpt" or path.exists():
        if not path.is_file():
            raise InputError(spec, "model checkpoint not found")
        try:
            return TrajectoryRNN.load_from_checkpoint(str(path), map_location="cpu").eval()
        except Exception as err:  # torch and Lightning raise many kinds
            raise InputError(spec, f"not a trajectory RNN checkpoint ({type(err).__name__}: {str(err).splitlines()[0][:120]})") from err
    uri = spec if "://" in spec or spec.startswith(("runs:/", "models:/")) else f"runs:/{spec}/model"
    import mlflow  # only for run ids and model URIs: MLflow is slow to import
    import mlflow.artifacts
    import mlflow.exceptions

    store = tracking_uri or default_uri()
    if store.startswith("sqlite:///"):
        db = Path(store[len("sqlite:///"):].split("?")[0])
        if not db.is_file():
            raise InputError(spec, f"no MLflow store at {db} to look up the run id in (set --tracking-uri or MLFLOW_TRACKING_URI)")
    mlflow.set_tracking_uri(store)
    if uri.startswith("runs:/"):  # the Lightning checkpoint the stage logged beside the model (log_checkpoint)
        run_id = uri[len("runs:/"):].split("/")[0]
        try:
            local = mlflow.artifacts.download_artifacts(run_id=run_id, artifact_path=f"{CHECKPOINT_ARTIFACT}/model.ckpt")
        except (mlflow.exceptions.MlflowException, OSError):  # no such run or no checkpoint: try the logged model
            local = None
        if local is not None:
            return TrajectoryRNN.load_from_checkpoint(local, map_location="cpu").eval()
    try:
        model = mlflow.pytorch.load_model(uri, map_location="cpu")
    except Exception as err:  # MlflowException and OSError for unknown runs, models and artifacts
        first = str(err).splitlines()[0][:160] if str(err) else type(err).__name__
        raise InputError(spec, f"no trajectory model at {uri} in the MLflow store {store.split('?')[0]} ({first})") from err
    if not isinstance(model, TrajectoryRNN):  # recent MLflow logs an exported graph: no hyper-parameters, no states
        raise InputError(spec, f"{uri} is a {type(model).__name__}, not the trajectory RNN: load its run's checkpoint "
                               f"({CHECKPOINT_ARTIFACT}/model.ckpt) or the stage's model.ckpt")
    return model.eval()


def log_checkpoint(path: str | Path) -> None:
    """Attach the checkpoint ``path`` to the active MLflow run as ``checkpoint/model.ckpt``, what
    :func:`load_model` of a run id loads (the MLflow model alone may be an exported graph without the
    hyper-parameters and recurrent states the localizers need)."""
    import mlflow

    mlflow.log_artifact(str(path), CHECKPOINT_ARTIFACT)
