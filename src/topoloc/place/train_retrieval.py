"""Stage ``train_retrieval``: fit the siamese place-recognition network with Lightning.

Data: the ``train`` place set (:mod:`topoloc.place.images`), served by :class:`topoloc.place.pair_data.PairData`.
Its last ``train.val_routes`` routes are for validation; the others for training, with pairs
(:mod:`topoloc.place.pairs`) drawn among the conditions of ``train.conditions`` only. Every epoch draws
``train.batches_per_epoch`` fresh batches of ``train.batch_size`` pairs (seeded by ``train.seed`` and the
epoch). With ``pairs.in_batch`` (default) the pairs of a batch are positives whose anchors come in groups from
one street, and the loss is the cross-entropy of *every* anchor against *every* partner of the batch, labelled
by the 2 m rule and balanced between the two labels (batch 32 gives 32 positives and about 790 negatives, a
tenth of them hard, per 64 images embedded; pairs under the same condition are left out, as for the
positives); without it, the sampler's positive / negative pairs are used one by one.

Validation: ``val/loss`` / ``val/acc`` on pairs of the validation routes among the training conditions
(this picks the checkpoint); ``val/acc_<condition>`` on pairs of a training condition against each
condition, held-out ones included (reported, never used for selection). After training,
``window_top1_<condition>``: on the validation routes, the share of places whose best-scoring place
within ``localize.window`` places of the teach condition's sequence lies within 5 m (the localization's
window search, with the truth at the window centre).

Trained by :func:`topoloc.training.fit` (the path shared with ``train_rnn``): the best checkpoint is written to
``model`` and logged to MLflow as a PyTorch model with its signature; ``metrics`` holds its ``best/val/*`` figures.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from topoloc.errors import InputError
from topoloc.io import atomic_path, write_json
from topoloc.place.images import PlaceSet
from topoloc.place.network import SiameseNet
from topoloc.place.pair_data import EpochSetter, PairData
from topoloc.place.plot import training_figure
from topoloc.render.conditions import check_conditions
from topoloc.training import FitSettings, LoggedModel
from topoloc.training import fit as fit_module

log = logging.getLogger(__name__)


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
    if net["weights"]:
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


def fit(conf: dict[str, Any], places: PlaceSet, model_path: str, fast_dev_run: bool = False,
        log_model: bool = False) -> tuple[SiameseNet, pd.DataFrame, dict[str, float]]:
    """Train on ``places``; write the best checkpoint to ``model_path``; return the model, history and metrics.

    Inside an active MLflow run the metrics go to it, and with ``log_model`` the model too.
    """
    train = conf["train"]
    names = check_conditions(conf)
    torch.set_num_threads(int(conf["threads"]))
    data = PairData(places, names["train"], train, conf["pairs"])
    settings = FitSettings.from_config(train, gradient_clip=None, early_stopping_patience=None, sanity_val_steps=0,
                                       fast_dev_run=fast_dev_run)
    logged = LoggedModel(signature_example(places), free_axes=1) if log_model else None
    result = fit_module(lambda: build_model(conf, places.images.shape[-1], places.conditions), data, settings,
                        model_path, callbacks=[EpochSetter(data.batches)], logged_model=logged)
    model = result.module
    metrics = result.metrics | {"train_places": float(len(data.train_idx)), "val_places": float(len(data.val_idx))}
    cond_index = {name: i for i, name in enumerate(places.conditions)}
    teach = names["teach"][0] if names["teach"] else None
    reference = cond_index[teach] if teach in cond_index else data.train_conditions[0]
    metrics |= window_top1(model, places, data.val_idx, reference, int(conf["localize"]["window"]))
    return model, result.history, metrics


def signature_example(places: PlaceSet) -> np.ndarray:
    """Two pairs ``(2, 2, C, H, W)`` float32 for the logged model's signature: the first and last condition of the
    first two places."""
    pairs = np.stack([places.images[0, :2], places.images[-1, :2]], axis=1).astype(np.float32)
    return np.ascontiguousarray(pairs.transpose(0, 1, 4, 2, 3))


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train on ``inputs['places']``; write ``model``, ``history``, ``metrics`` and ``figure``."""

    places = PlaceSet.load(inputs["places"])
    _, history, metrics = fit(conf, places, outputs["model"], log_model=conf["train"]["log_model"])
    with atomic_path(outputs["history"]) as tmp:
        history.to_csv(tmp, index=False)
    write_json(outputs["metrics"], metrics)
    training_figure(history, metrics, outputs["figure"])
    log.info("trained: %s", metrics)
    return metrics
