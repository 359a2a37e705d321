"""The data of ``train_retrieval``: pair batches for training, fixed pairs for validation, as a DataModule.

The last ``val_routes`` routes of the ``train`` place set are for validation, the others for training. Every
epoch draws ``batches_per_epoch`` fresh batches of ``batch_size`` pairs (seeded by ``seed`` and the epoch) among
the training conditions (:class:`PairBatches`; :class:`EpochSetter` tells it the epoch). Validation has two
loaders of fixed pairs on the validation routes: among the training conditions (``val/loss``, ``val/acc``), and a
training condition against each condition, held-out ones included (``val/acc_<condition>``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from topoloc.errors import InputError
from topoloc.place.images import PlaceSet
from topoloc.place.pairs import IGNORE, Pairs, PairSampler


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


class FixedPairs(Dataset):
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


class PairData(L.LightningDataModule):
    """Training batches and validation pairs of ``places`` (a ``train`` place set) for the siamese network.

    ``train_conditions``: the condition names pairs are drawn among; ``train`` and ``pairs``: the
    ``place.train`` and ``place.pairs`` config slices.
    """

    def __init__(self, places: PlaceSet, train_conditions: list[str], train: Mapping[str, Any],
                 pairs: Mapping[str, Any]) -> None:
        super().__init__()
        missing = [c for c in train_conditions if c not in places.conditions]
        if missing:
            raise InputError("place.train.conditions", f"{missing} not rendered in the training set ({places.conditions})")
        routes = np.unique(places.route)
        val_routes = int(train["val_routes"])
        if not 0 < val_routes < len(routes):
            raise InputError("place.train.val_routes", f"needs 1..{len(routes) - 1} of the {len(routes)} training routes")
        is_val = np.isin(places.route, routes[-val_routes:])
        self.places = places
        self.train_idx, self.val_idx = np.flatnonzero(~is_val), np.flatnonzero(is_val)
        cond_index = {name: i for i, name in enumerate(places.conditions)}
        self.train_conditions = [cond_index[c] for c in train_conditions]
        self.pairs_conf = dict(pairs)
        seed = int(train["seed"])
        self.batches = PairBatches(places.images, self.train_idx, self._sampler(self.train_idx, self.train_conditions),
                                   int(train["batches_per_epoch"]), int(train["batch_size"]), seed,
                                   bool(pairs["in_batch"]), int(pairs["cluster"]))
        val_sampler = self._sampler(self.val_idx, list(range(len(places.conditions))))
        n_val = int(train["val_pairs"])
        train_c = self.train_conditions
        self.val_pairs = [validation_pairs(val_sampler, self.val_idx, train_c, train_c, max(1, n_val // len(train_c)), seed),
                          validation_pairs(val_sampler, self.val_idx, train_c, list(range(len(places.conditions))), n_val,
                                           seed + 1)]

    def _sampler(self, idx: np.ndarray, conditions: list[int]) -> PairSampler:
        p = self.pairs_conf
        return PairSampler(self.places.xy[idx], self.places.yaw[idx], conditions, float(p["positive_m"]),
                           tuple(p["hard_negative_m"]), float(p["hard_share"]), float(p["max_heading_deg"]))

    def train_dataloader(self) -> DataLoader:
        return DataLoader(self.batches, batch_size=None, shuffle=False)

    def val_dataloader(self) -> list[DataLoader]:
        return [DataLoader(FixedPairs(self.places.images, self.val_idx, pairs), batch_size=256, shuffle=False)
                for pairs in self.val_pairs]
