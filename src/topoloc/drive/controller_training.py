"""Training a controller, Topo-DLM (:mod:`topoloc.drive.controller`) or Topo-LP (:mod:`topoloc.drive.topo_lp`), on the
expert's demonstrations, its DAgger rounds and its closed-loop check (the library of ``train_controller``).

Data (:class:`DemoData`): the last ``demonstrations.val_routes`` routes of the demonstrations are for validation
(``val/loss``, ``val/steer_mae`` pick the checkpoint), the others for training. Every epoch draws
``train.batches_per_epoch`` batches of ``train.batch_size`` steps with the commands balanced (each command
present in the data is drawn equally often: turns are rare), seeded by ``train.seed``. The steps of a controller told
a path (Topo-LP, and Topo-DLM told the move) carry the local-path plane of their lane path with the training noise of
``drive.path_noise`` (:class:`PathSteps`).

:func:`fit` trains by :func:`topoloc.training.fit` (the shared Lightning path) and writes the best checkpoint;
:func:`dagger_rounds` drives, labels and trains on (:mod:`topoloc.drive.on_policy`); :func:`check_controller` is the
closed-loop check on routes the controller never saw.
"""

from __future__ import annotations

import logging
from typing import Any

import lightning as L
import numpy as np
import pandas as pd
import torch
from torch.utils.data import DataLoader, Dataset, TensorDataset, WeightedRandomSampler

from topoloc.drive.controller import TopoDLM, waypoint_targets
from topoloc.drive.demonstrations import Demonstrations
from topoloc.drive.local_path import path_input
from topoloc.drive.on_policy import DaggerSettings, closed_loop_check, collect
from topoloc.drive.routes import make_simulator, teach_route
from topoloc.drive.topo_lp import TopoLP, controller_class
from topoloc.drive.turn_routes import TrainingRoutes
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.place.topometric_map import COMMANDS
from topoloc.training import FitSettings, LoggedModel
from topoloc.training import fit as fit_module

log = logging.getLogger(__name__)

#: Bins of |steer| that ``train.steer_balance`` draws equally often.
STEER_BINS = np.array([0.1, 0.2, 0.35, 0.5])


def _targets(demos: Demonstrations, idx: np.ndarray, max_speed: float) -> np.ndarray:
    """Labels per step: steer, target speed / max speed, then the scaled waypoints (:func:`waypoint_targets`)."""
    return np.column_stack([demos.steer[idx], demos.target_speed[idx] / max_speed,
                            waypoint_targets(demos.path[idx])]).astype(np.float32)


def _tensors(demos: Demonstrations, idx: np.ndarray, max_speed: float) -> TensorDataset:
    return TensorDataset(torch.from_numpy(np.ascontiguousarray(demos.images[idx])), torch.from_numpy(demos.speed[idx]),
                         torch.from_numpy(demos.command[idx]), torch.from_numpy(_targets(demos, idx, max_speed)))


class PathSteps(Dataset):
    """Steps with their local-path plane (:func:`path_input`, told in ``form``): the lane path in the lane's frame
    shifted along it by N(0, ``shift_m``) and turned by N(0, ``yaw_deg``) per draw (the localization error of the
    paper's training), or in the vehicle's frame (``frame: aligned``) moved by N(0, ``shift_m``) ahead, N(0,
    ``lateral_m``) aside and turned by N(0, ``yaw_deg``) (the pose tracker's error). With ``fixed`` every step keeps
    one draw (validation: the same data every epoch, so epochs compare)."""

    def __init__(self, demos: Demonstrations, idx: np.ndarray, max_speed: float, shift_m: float, yaw_deg: float,
                 seed: int, fixed: bool = False, lateral_m: float = 0.0, frame: str = "lane", form: str = "path") -> None:
        self.demos, self.idx, self.target = demos, idx, _targets(demos, idx, max_speed)
        self.shift_m, self.yaw, self.lateral_m, self.frame = float(shift_m), np.radians(float(yaw_deg)), float(lateral_m), frame
        self.form = form
        self.seed, self.fixed = int(seed), bool(fixed)
        self.rng = np.random.default_rng([seed, 61])

    def __len__(self) -> int:
        return len(self.idx)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, ...]:
        k = int(self.idx[i])
        rng = np.random.default_rng([self.seed, 61, i]) if self.fixed else self.rng
        shift = float(rng.normal(0.0, self.shift_m)) if self.shift_m else 0.0
        turn = float(rng.normal(0.0, self.yaw)) if self.yaw else 0.0
        aside = float(rng.normal(0.0, self.lateral_m)) if self.lateral_m and self.frame == "aligned" else 0.0
        path = path_input(self.demos.path[k], self.frame, shift, aside, turn, self.form)
        return (torch.from_numpy(self.demos.images[k]), torch.tensor(self.demos.speed[k]), torch.from_numpy(path),
                torch.from_numpy(self.target[i]))


class DemoData(L.LightningDataModule):
    """Command-balanced training batches and the validation routes' steps in order."""

    def __init__(self, demos: Demonstrations, val_routes: int, train: dict[str, Any], max_speed: float,
                 path_noise: dict[str, Any] | None = None) -> None:
        super().__init__()
        routes = np.unique(demos.route)
        if len(routes) <= val_routes:
            raise InputError("drive.demonstrations.val_routes", f"the demonstrations hold {len(routes)} routes; "
                             f"{val_routes} for validation leaves none to train on")
        val = np.isin(demos.route, routes[len(routes) - val_routes:])
        self.train_idx, self.val_idx = np.flatnonzero(~val), np.flatnonzero(val)
        if not len(self.val_idx):
            raise InputError("drive.demonstrations.val_routes", "no validation step")
        self.demos, self.train_conf, self.max_speed, self.path_noise = demos, train, max_speed, path_noise
        counts = np.bincount(demos.command[self.train_idx], minlength=len(COMMANDS)).astype(float)
        self.weights = 1.0 / counts[demos.command[self.train_idx]]
        if train.get("steer_balance"):  # sharp bends are rare under every command: draw them as often as straight on
            bins = np.digitize(np.abs(demos.steer[self.train_idx]), STEER_BINS)
            self.weights = self.weights / np.bincount(bins, minlength=len(STEER_BINS) + 1)[bins]

    def train_dataloader(self) -> DataLoader:
        batch = int(self.train_conf["batch_size"])
        generator = torch.Generator().manual_seed(int(self.train_conf["seed"]))
        sampler = WeightedRandomSampler(self.weights.tolist(), batch * int(self.train_conf["batches_per_epoch"]),
                                        replacement=True, generator=generator)
        return DataLoader(self._steps(self.train_idx, 0), batch_size=batch, sampler=sampler)

    def val_dataloader(self) -> DataLoader:
        return DataLoader(self._steps(self.val_idx, 1), batch_size=256)

    def _steps(self, idx: np.ndarray, stream: int) -> Dataset:
        if self.path_noise is None:
            return _tensors(self.demos, idx, self.max_speed)
        noise = self.path_noise
        return PathSteps(self.demos, idx, self.max_speed, noise["shift_m"], noise["yaw_deg"],
                         int(self.train_conf["seed"]) * 2 + stream, fixed=stream == 1,
                         lateral_m=noise.get("lateral_m", 0.0), frame=noise.get("frame", "lane"),
                         form=noise.get("form", "path"))


def path_noise(drive: dict[str, Any], agent: str) -> dict[str, Any] | None:
    """What :class:`DemoData` needs of ``drive.path_noise`` and ``drive.network`` to tell controller ``agent`` its path:
    the noise, the frame and the form (the path, or Topo-DLM's move); None for a controller told a command (the
    discrete Topo-DLM)."""
    if controller_class(agent, str(drive["network"]["dlm_command"])) is not TopoLP:
        return None
    return ({k: float(v) for k, v in drive["path_noise"].items()}
            | {"frame": str(drive["network"]["path_frame"]), "form": "path" if agent == "lp" else "move"})


def build_model(drive: dict[str, Any], demos: Demonstrations, agent: str = "dlm") -> TopoDLM:
    """The controller ``agent`` (``dlm``, ``lp``) of ``drive.network`` with the settings of ``drive.train`` for images
    shaped like ``demos``' (:func:`topoloc.drive.topo_lp.controller_class` says which network)."""
    net, train = drive["network"], drive["train"]
    h, w, c = demos.images.shape[1:]
    told = path_noise(drive, agent)
    extra = {"image_dropout": float(train["image_dropout"]), "path_prior": bool(net["path_prior"]),
             "path_frame": told["frame"], "path_form": told["form"]} if told else {}
    cls = controller_class(agent, str(net["dlm_command"]))
    return cls(**extra, in_channels=c, height=h, width=w, channels=list(net["channels"]),
               hidden=int(net["hidden"]), downsample=int(net["downsample"]),
               dropout=float(net["dropout"]), max_speed=float(drive["vehicle"]["max_speed_mps"]),
               speed_gain=float(drive["expert"]["speed_gain"]), lr=float(train["lr"]),
               weight_decay=float(train["weight_decay"]), steer_weight=float(train["steer_weight"]),
               speed_weight=float(train["speed_weight"]), augment=bool(train["augment"]), seed=int(train["seed"]),
               output=str(net["output"][agent]), wheelbase=float(drive["vehicle"]["wheelbase_m"]),
               max_steer_deg=float(drive["vehicle"]["max_steer_deg"]), lookahead_s=float(drive["expert"]["lookahead_s"]),
               min_lookahead_m=float(drive["expert"]["min_lookahead_m"]))


def signature_example(demos: Demonstrations, told: dict[str, Any] | None = None) -> np.ndarray:
    """Two steps as the logged model's input ``(2, C + 2, H, W)`` float32: image, speed plane, command plane (the
    discrete Topo-DLM: ``told`` None) or local-path plane (a controller told a path, ``told`` its
    :func:`path_noise`: :func:`topoloc.drive.local_path.path_plane` in its top-left corner)."""
    images = demos.images[:2].astype(np.float32).transpose(0, 3, 1, 2)
    planes = np.ones((len(images), 2, *images.shape[2:]), np.float32)
    planes[:, 0] *= demos.speed[:2, None, None]
    if told is not None:
        planes[:, 1] = 0.0
        for i in range(len(images)):
            path = path_input(demos.path[i], told["frame"], form=told["form"])[: images.shape[2], : images.shape[3]]
            planes[i, 1, : path.shape[0], : path.shape[1]] = path
    else:
        planes[:, 1] *= demos.command[:2, None, None]
    return np.ascontiguousarray(np.concatenate([images, planes], axis=1))


def fit(drive: dict[str, Any], demos: Demonstrations, model_path: str, log_model: bool = False,
        fast_dev_run: bool = False, agent: str = "dlm",
        init: TopoDLM | None = None) -> tuple[TopoDLM, pd.DataFrame, dict[str, float]]:
    """Train controller ``agent`` (from the weights of ``init`` when given) on ``demos``; write the best checkpoint to
    ``model_path``; return the model, history and metrics."""
    train = drive["train"]
    torch.set_num_threads(int(drive["threads"]))
    noise = path_noise(drive, agent)
    data = DemoData(demos, int(drive["demonstrations"]["val_routes"]), train, float(drive["vehicle"]["max_speed_mps"]),
                    noise)
    settings = FitSettings.from_config(train, gradient_clip=1.0, early_stopping_patience=None, sanity_val_steps=0,
                                       fast_dev_run=fast_dev_run)
    logged = LoggedModel(signature_example(demos, noise), free_axes=1) if log_model else None
    if init is not None:
        init.train()  # a loaded or acted-with model is in eval mode, and Lightning keeps a module's mode
    result = fit_module(lambda: init if init is not None else build_model(drive, demos, agent), data, settings, model_path,
                        logged_model=logged)
    metrics = result.metrics | {"train_steps": float(len(data.train_idx)), "val_steps": float(len(data.val_idx))}
    return result.module, result.history, metrics


def _route_makers(conf: dict[str, Any], inputs: dict[str, str]) -> tuple[Any, Any, Any]:
    """The teach route's lane points (kept away from), and the makers of training routes and their simulators."""
    graph = RoadGraph.load(inputs["graph"])
    osm = inputs.get("osm")
    length = float(conf["drive"]["demonstrations"]["route_length_m"])
    return (teach_route(graph, conf).xy, TrainingRoutes(graph, conf, length),
            lambda route: make_simulator(osm, graph, route, conf))


def check_controller(conf: dict[str, Any], inputs: dict[str, str], model: TopoDLM) -> dict[str, float]:
    """The closed-loop check of ``model`` on unseen routes of the region of ``inputs`` (``osm``, ``graph``;
    :func:`topoloc.drive.on_policy.closed_loop_check`)."""
    avoid, make_route, make_sim = _route_makers(conf, inputs)
    return closed_loop_check(model.eval(), conf, avoid, make_route, make_sim)


def dagger_rounds(conf: dict[str, Any], inputs: dict[str, str], model_path: str, model: TopoDLM, demos: Demonstrations,
                  history: pd.DataFrame, metrics: dict[str, float],
                  log_model: bool) -> tuple[TopoDLM, pd.DataFrame, dict[str, float]]:
    """The DAgger rounds of :mod:`topoloc.drive.on_policy` after the first fit: the last round's model, the history of
    every fit (steps counted on, ``round`` 0 the first fit) and the metrics (the last fit's, and each round's
    ``dagger/<k>/...``)."""
    drive = conf["drive"]
    settings = DaggerSettings.from_conf(drive["dagger"])
    agent = str(conf.get("controller", "dlm"))
    avoid, make_route, make_sim = _route_makers(conf, inputs)
    round_drive = {**drive, "train": {**drive["train"], "max_epochs": settings.epochs}}
    histories, facts_all = [history.assign(round=0)], {}
    for k in range(settings.rounds):
        steps, facts = collect(model, conf, k, avoid, make_route, make_sim)
        log.info("DAgger round %d: %s", k + 1, facts)
        facts_all |= {f"dagger/{k + 1}/{key}": value for key, value in facts.items()}
        if len(steps):
            demos = Demonstrations.concat([demos, steps])
        model, fitted, metrics = fit(round_drive, demos, model_path, log_model=log_model and k == settings.rounds - 1,
                                     agent=agent, init=model)
        offset = float(histories[-1].step.max()) + 1.0 if len(histories[-1]) else 0.0
        histories.append(fitted.assign(step=fitted.step + offset, round=k + 1))
    return model, pd.concat(histories, ignore_index=True), metrics | facts_all
