"""Stage ``train_retrieval``: fit the siamese place-recognition network with Lightning.

Data: the ``train`` place set (:mod:`topoloc.place.images`). Its last ``train.val_routes`` routes are for
validation; the others for training, with pairs (:mod:`topoloc.place.pairs`) drawn among the conditions of
``train.conditions`` only. Every epoch draws ``train.batches_per_epoch`` fresh batches of
``train.batch_size`` pairs (seeded by ``train.seed`` and the epoch). With ``pairs.in_batch`` (default) the
pairs of a batch are positives whose anchors come in groups from one street, and the loss is the
cross-entropy of *every* anchor against *every* partner of the batch, labelled by the 2 m rule and
balanced between the two labels (batch 32 gives 32 positives and about 790 negatives, a tenth of them
hard, per 64 images embedded; pairs under the same condition are left out, as for the positives); without it, the sampler's positive / negative pairs are used one by one.

Validation: ``val_loss`` / ``val_acc`` on pairs of the validation routes among the training conditions
(this picks the checkpoint); ``val_acc_<condition>`` on pairs of a training condition against each
condition, held-out ones included (reported, never used for selection). After training,
``window_top1_<condition>``: on the validation routes, the share of places whose best-scoring place
within ``localize.window`` places of the teach condition's sequence lies within 5 m (the localization's
window search, with the truth at the window centre).

The best checkpoint is written to ``model`` and logged to MLflow as a PyTorch model with its signature.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import pandas as pd
import torch
from torch.utils.data import DataLoader, Dataset

from topoloc.training import History, best_checkpoint, keep_best
from topoloc.errors import InputError
from topoloc.io import atomic_path, write_json
from topoloc.place.images import PlaceSet
from topoloc.place.pairs import IGNORE, PairSampler, Pairs
from topoloc.render.conditions import check_conditions
from topoloc.tracking import tracking_uri
from topoloc.place.network import SiameseNet
from topoloc.place.plot import training_figure

log = logging.getLogger(__name__)


class PairBatches(Dataset):
    """Whole batches of pairs (one item = one batch), redrawn every epoch from ``(seed, epoch, index)``."""

    def __init__(self, images: np.ndarray, places: np.ndarray, sampler: PairSampler, batches: int, batch_size: int,
                 seed: int, in_batch: bool, cluster: int) -> None:
        self.images, self.places, self.sampler = images, places, sampler
        self.batches, self.batch_size, self.seed = int(batches), int(batch_size), int(seed)
        self.in_batch, self.cluster = bool(in_batch), int(cluster)
        self.epoch = 0

    def __len__(self) -> int:
        return self.batches

    def __getitem__(self, index: int) -> tuple[torch.Tensor, ...]:
        rng = np.random.default_rng([self.seed, self.epoch, index])
        if self.in_batch:
            pairs = self.sampler.sample_clustered(self.batch_size, self.cluster, rng)
            labels = self.sampler.label_matrix(pairs.place_a, pairs.place_b)
            # Like the positives, every pair is across conditions: were same-condition pairs kept, nearly all of
            # them would be negatives, and "same condition" would mean "different place" to the network.
            labels[pairs.cond_a[:, None] == pairs.cond_b[None]] = IGNORE
        else:
            pairs = self.sampler.sample(self.batch_size, rng)
            labels = pairs.label
        return (*pair_tensors(self.images, self.places, pairs), torch.from_numpy(labels))


def pair_tensors(images: np.ndarray, places: np.ndarray, pairs: Pairs) -> tuple[torch.Tensor, torch.Tensor]:
    """uint8 image batches ``(N, H, W, C)`` of both sides of ``pairs`` (``places`` maps sampler to set indices)."""
    a = images[pairs.cond_a, places[pairs.place_a]]
    b = images[pairs.cond_b, places[pairs.place_b]]
    return torch.from_numpy(np.ascontiguousarray(a)), torch.from_numpy(np.ascontiguousarray(b))


class EpochSetter(L.Callback):
    """Tells the batch dataset which epoch it is (fresh pairs every epoch)."""

    def __init__(self, dataset: PairBatches) -> None:
        self.dataset = dataset

    def on_train_epoch_start(self, trainer: L.Trainer, module: L.LightningModule) -> None:
        self.dataset.epoch = trainer.current_epoch


def validation_pairs(sampler: PairSampler, places: np.ndarray, anchor_conditions: list[int], conditions: list[int],
                     n: int, seed: int) -> list[Pairs]:
    """Fixed pairs for each condition index in ``conditions``: a training condition against that condition."""
    out = []
    for c in conditions:
        rng = np.random.default_rng([seed, 5, c])
        p = sampler.sample(n, rng)
        others = [a for a in anchor_conditions if a != c]
        cond_a = np.asarray(others, np.int64)[rng.integers(0, len(others), n)]
        out.append(Pairs(p.place_a, cond_a, p.place_b, np.full(n, c, np.int64), p.label))
    return out


class _Fixed(Dataset):
    """Fixed pairs as items ``(a, b, label, condition)``."""

    def __init__(self, images: np.ndarray, places: np.ndarray, pairs: list[Pairs]) -> None:
        self.items = []
        for p in pairs:
            a, b = pair_tensors(images, places, p)
            for k in range(len(p)):
                self.items.append((a[k], b[k], int(p.label[k]), int(p.cond_b[k])))

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> tuple[Any, ...]:
        return self.items[index]


def build_model(conf: dict[str, Any], in_channels: int, names: list[str]) -> SiameseNet:
    """The network of ``conf['network']`` with the optimizer settings of ``conf['train']``; local ``weights`` loaded."""
    net, train = conf["network"], conf["train"]
    if net["head_init"] == "metric" and int(net["hidden"]) < 2 * int(net["embedding_dim"]):
        raise InputError("place.network.hidden", f"a metric head needs at least 2 x embedding_dim = "
                         f"{2 * int(net['embedding_dim'])} hidden units, got {net['hidden']}")
    model = SiameseNet(in_channels=in_channels, channels=list(net["channels"]), embedding_dim=int(net["embedding_dim"]),
                       pool=list(net["pool"]), hidden=int(net["hidden"]), normalize=str(net["normalize"]),
                       embedding_scale=float(net["embedding_scale"]), head_init=str(net["head_init"]),
                       lr=float(train["lr"]), lr_decay=float(train["lr_decay"]), weight_decay=float(train["weight_decay"]),
                       augment=bool(train["augment"]), seed=int(train["seed"]))
    model.condition_names = list(names)
    if net.get("weights"):
        path = Path(net["weights"])
        if not path.is_file():
            raise InputError("place.network.weights", f"{path}: weights file not found")
        state = torch.load(path, map_location="cpu", weights_only=True)
        state = state.get("state_dict", state)
        try:
            missing, unexpected = model.load_state_dict(state, strict=False)
        except RuntimeError as err:
            raise InputError("place.network.weights", f"{path}: does not fit the configured network ({str(err)[:200]})") from err
        log.info("loaded weights %s (missing %d, unexpected %d keys)", path, len(missing), len(unexpected))
    return model


@torch.no_grad()
def window_top1(model: SiameseNet, places: PlaceSet, idx: np.ndarray, reference: int, window: int,
                radius_m: float = 5.0) -> dict[str, float]:
    """Per condition: share of places whose best match within ``window`` places (same route, condition ``reference``) is within ``radius_m``."""
    out = {}
    ref = model.embed(places.images[reference, idx])
    route = places.route[idx]
    for c, name in enumerate(places.conditions):
        if c == reference:
            continue
        query = model.embed(places.images[c, idx])
        hits = []
        for k in range(len(idx)):
            w = np.arange(max(0, k - window), min(len(idx), k + window + 1))
            w = w[route[w] == route[k]]
            j = w[int(np.argmax(model.same_place(query[k], ref[w])))]
            hits.append(np.hypot(*(places.xy[idx[j]] - places.xy[idx[k]])) <= radius_m)
        out[f"window_top1_{name}"] = float(np.mean(hits))
    return out


def fit(conf: dict[str, Any], places: PlaceSet, model_path: str, logger: Any = None,
        fast_dev_run: bool = False) -> tuple[SiameseNet, pd.DataFrame, dict[str, float]]:
    """Train on ``places``; write the best checkpoint to ``model_path``; return the model, history and metrics."""
    train, pairs_conf = conf["train"], conf["pairs"]
    names = check_conditions(conf)
    L.seed_everything(int(train["seed"]), workers=True, verbose=False)
    torch.set_num_threads(int(conf["threads"]))
    missing = [c for c in names["train"] if c not in places.conditions]
    if missing:
        raise InputError("place.train.conditions", f"{missing} not rendered in the training set ({places.conditions})")
    routes = np.unique(places.route)
    val_routes = int(train["val_routes"])
    if not 0 < val_routes < len(routes):
        raise InputError("place.train.val_routes", f"needs 1..{len(routes) - 1} of the {len(routes)} training routes")
    is_val = np.isin(places.route, routes[-val_routes:])
    train_idx, val_idx = np.flatnonzero(~is_val), np.flatnonzero(is_val)
    cond_index = {name: i for i, name in enumerate(places.conditions)}
    train_c = [cond_index[c] for c in names["train"]]

    def sampler(idx: np.ndarray, conditions: list[int]) -> PairSampler:
        return PairSampler(places.xy[idx], places.yaw[idx], conditions, float(pairs_conf["positive_m"]),
                           tuple(pairs_conf["hard_negative_m"]), float(pairs_conf["hard_share"]),
                           float(pairs_conf["max_heading_deg"]))

    batches = PairBatches(places.images, train_idx, sampler(train_idx, train_c), int(train["batches_per_epoch"]),
                          int(train["batch_size"]), int(train["seed"]), bool(pairs_conf["in_batch"]),
                          int(pairs_conf["cluster"]))
    val_sampler = sampler(val_idx, list(range(len(places.conditions))))
    n_val = int(train["val_pairs"])
    seen = validation_pairs(val_sampler, val_idx, train_c, train_c, max(1, n_val // len(train_c)), int(train["seed"]))
    every = validation_pairs(val_sampler, val_idx, train_c, list(range(len(places.conditions))), n_val, int(train["seed"]) + 1)
    loaders = [DataLoader(_Fixed(places.images, val_idx, pairs), batch_size=256, shuffle=False)
               for pairs in (seen, every)]
    model = build_model(conf, places.images.shape[-1], places.conditions)
    history = History(every=max(1, int(train["log_every_n_steps"])))
    max_time = train.get("max_time_min")
    with best_checkpoint(model_path) as checkpoint:
        trainer = L.Trainer(
            accelerator=train["accelerator"], devices=1, max_epochs=int(train["max_epochs"]),
            max_time={"minutes": float(max_time)} if max_time is not None else None,
            logger=logger if logger is not None else False, callbacks=[history, checkpoint, EpochSetter(batches)],
            log_every_n_steps=int(train["log_every_n_steps"]), enable_progress_bar=True, enable_model_summary=False,
            fast_dev_run=fast_dev_run, deterministic=True, num_sanity_val_steps=0,
        )
        started = time.perf_counter()
        trainer.fit(model, DataLoader(batches, batch_size=None, shuffle=False), loaders)
        seconds = time.perf_counter() - started
        model = keep_best(checkpoint, trainer, model_path, model)
    model.condition_names = list(places.conditions)
    frame = pd.DataFrame(history.rows)
    metrics = {"train_seconds": seconds, "epochs": float(trainer.current_epoch), "steps": float(trainer.global_step),
               "train_places": float(len(train_idx)), "val_places": float(len(val_idx)),
               "parameters": float(sum(p.numel() for p in model.parameters()))}
    if "val_loss" in frame:
        rows = frame.dropna(subset=["val_loss"])
        best_row = rows.loc[rows.val_loss.idxmin()]
        metrics |= {k: float(best_row[k]) for k in rows.columns if k.startswith("val_") and pd.notna(best_row[k])}
        metrics["best_epoch"] = float(best_row.epoch)
    window = int(conf["localize"]["window"])
    teach = names["teach"][0] if names["teach"] else None
    reference = cond_index[teach] if teach in cond_index else train_c[0]
    metrics |= window_top1(model, places, val_idx, reference, window)
    return model, frame, metrics


def log_mlflow_model(model: SiameseNet, example: np.ndarray) -> None:
    """Log ``model`` to the active MLflow run as a PyTorch model with a signature (pairs -> probabilities)."""
    import mlflow
    from mlflow.models import ModelSignature
    from mlflow.types import Schema, TensorSpec

    model = model.to("cpu").eval()
    example = example.astype(np.float32)
    h, w, c = example.shape[-3:]
    signature = ModelSignature(inputs=Schema([TensorSpec(np.dtype(np.float32), (-1, 2, c, h, w))]),
                               outputs=Schema([TensorSpec(np.dtype(np.float32), (-1, 2))]))
    pairs = np.ascontiguousarray(example.transpose(0, 1, 4, 2, 3))
    mlflow.pytorch.log_model(model, name="model", signature=signature, input_example=pairs)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train on ``inputs['places']``; write ``model``, ``history``, ``metrics`` and ``figure``."""
    import mlflow  # the MLflow client is slow to import: only when the stage runs
    from lightning.pytorch.loggers import MLFlowLogger

    places = PlaceSet.load(inputs["places"])
    active = mlflow.active_run()
    logger = MLFlowLogger(tracking_uri=tracking_uri(), run_id=active.info.run_id) if active else None
    model, history, metrics = fit(conf, places, outputs["model"], logger)
    with atomic_path(outputs["history"]) as tmp:
        history.to_csv(tmp, index=False)
    write_json(outputs["metrics"], metrics)
    training_figure(history, metrics, outputs["figure"])
    log.info("trained: %s", metrics)
    if active and conf["train"].get("log_model", True):
        example = np.stack([places.images[0, :2], places.images[-1, :2]], axis=1)
        log_mlflow_model(model, example)
    return metrics
