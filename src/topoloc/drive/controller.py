"""Topo-DLM: the conditional imitation-learning controller of Cai & Wan (Codevilla et al.'s branched network), told
the discrete command (``drive.network.dlm_command: discrete``; told the move, Topo-DLM is
:class:`topoloc.drive.topo_lp.TopoLP`'s network, :func:`topoloc.drive.topo_lp.controller_class`).

* **Image encoder**: each image averaged over ``downsample`` x ``downsample`` pixels (the lane and the junctions
  ahead stay visible; the convolutions cost that factor squared less), normalised by its local contrast (:func:`topoloc.place.network.local_normalize`:
  most of a condition's brightness and colour cast drops out), then one stage per ``channels`` entry
  (3x3 convolution with stride 2, batch norm, ReLU, 3x3 convolution, batch norm, ReLU), flattened, a fully
  connected layer of ``hidden`` units with dropout.
* **Measurement encoder**: the speed (divided by ``max_speed``) through two layers of 64 units.
* **Joint layer** of ``hidden`` units, then one **branch** per navigation command (follow, left, right,
  straight; two layers) giving (steer, target speed); the command selects the branch. The throttle is
  ``speed_gain`` times the speed error, as the expert's (a network that gives the throttle itself learns that
  a car at rest stays at rest: the first steps of a drive are too few to teach it otherwise). A further head predicts
  the speed from the image alone (an auxiliary loss, as in Codevilla et al. 2019).
* **Output** (``output``): ``steer`` (the paper's: each branch gives the steering directly) or ``waypoints`` (a
  deviation from the paper, as in the waypoint / affordance variants of conditional imitation learning: each branch
  gives the lane's points :data:`WAYPOINT_ARCS` metres ahead in the vehicle frame, x ahead and y left, and the
  steering is the expert's pure-pursuit law on them, :func:`pure_pursuit`: the network learns where the lane is,
  not the gain of a controller; measured against ``steer`` in docs/route_following.md).
* **Loss**: ``steer_weight (steer - s)^2 + (1 - steer_weight) (v / max_speed - v')^2`` of the commanded branch
  (``v`` the expert's target speed; with ``waypoints`` the steering error is the mean squared error of the points,
  in units of :data:`WAYPOINT_SCALE_M`), plus
  ``speed_weight`` times the squared error of the speed prediction. Adam.

``forward`` takes one tensor ``(N, C + 2, H, W)``: the image (0..255) with two constant planes appended, the
speed in m/s and the command index; it returns ``(N, 2)`` (steer, target speed in m/s): the signature of the logged
MLflow model. :meth:`TopoDLM.act` is the closed-loop call. Plain torch, trained from scratch.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import lightning as L
import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn
from torch.nn import functional as F

from topoloc.errors import InputError
from topoloc.fast_inference import InferenceCopy
from topoloc.place.network import augment, eval_mode, local_normalize
from topoloc.place.topometric_map import COMMANDS

#: Arc lengths (m) along the lane, from the vehicle's progress, of the points the ``waypoints`` output predicts.
WAYPOINT_ARCS = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0)
#: The points are predicted in units of this many metres.
WAYPOINT_SCALE_M = 5.0
OUTPUTS = ("steer", "waypoints")
#: Display names of the agents, by the name the config and the outputs use.
AGENT_NAMES = {"dlm": "Topo-DLM", "lp": "Topo-LP", "replay": "replay"}


def waypoint_targets(path: NDArray[np.float32]) -> NDArray[np.float32]:
    """The ``waypoints`` labels ``(n, 2 K)`` (x, y of each arc of :data:`WAYPOINT_ARCS`, scaled) of recorded local
    paths ``(n, P, 2)`` (the lane 1, 2, ... P m ahead in the vehicle frame, :func:`topoloc.drive.demonstrations.local_path`)."""
    idx = np.asarray(WAYPOINT_ARCS, int) - 1
    return (np.asarray(path, np.float32)[:, idx].reshape(len(path), -1) / WAYPOINT_SCALE_M).astype(np.float32)


def pure_pursuit(points: torch.Tensor, speed: torch.Tensor, wheelbase: float, max_steer_deg: float, lookahead_s: float,
                 min_lookahead_m: float) -> torch.Tensor:
    """The expert's pure-pursuit steering (:class:`topoloc.drive.expert.Expert`) on lane points ``(N, 2 K)`` (scaled
    :data:`WAYPOINT_ARCS` points of the vehicle frame, whose origin is the middle of the wheelbase) at ``speed`` (N,).

    The expert aims at the lane point ``look = max(min_lookahead_m, lookahead_s v)`` beyond the rear axle's
    progress, about ``look - wheelbase / 2`` beyond the middle's; the point there is interpolated between the arcs."""
    pts = points.reshape(len(points), -1, 2) * WAYPOINT_SCALE_M
    arcs = torch.tensor(WAYPOINT_ARCS, dtype=pts.dtype, device=pts.device)
    look = torch.clamp(lookahead_s * speed.to(pts.dtype), min=min_lookahead_m)
    at = torch.clamp(look - 0.5 * wheelbase, WAYPOINT_ARCS[0], WAYPOINT_ARCS[-1])  # constants: torch.export (MLflow) traces it
    hi = torch.clamp(torch.searchsorted(arcs, at), 1, len(arcs) - 1)
    w = ((at - arcs[hi - 1]) / (arcs[hi] - arcs[hi - 1]))[:, None]
    rows = torch.arange(len(pts), device=pts.device)
    target = (1 - w) * pts[rows, hi - 1] + w * pts[rows, hi]
    alpha = torch.atan2(target[:, 1], target[:, 0] + 0.5 * wheelbase)
    delta = torch.atan2(2.0 * wheelbase * torch.sin(alpha), look)
    return torch.clamp(delta / np.radians(max_steer_deg), -1.0, 1.0)


def _stage(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, 2, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
                         nn.Conv2d(cout, cout, 3, 1, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class TopoDLM(L.LightningModule):
    """The branched controller of the module docstring."""

    def __init__(self, in_channels: int = 3, height: int = 48, width: int = 160, channels: Sequence[int] = (24, 32, 48, 64),
                 hidden: int = 256, dropout: float = 0.3, max_speed: float = 12.0, speed_gain: float = 0.5, lr: float = 1e-3,
                 weight_decay: float = 1e-4, steer_weight: float = 0.75, speed_weight: float = 0.1, augment: bool = True,
                 seed: int = 0, downsample: int = 1, output: str = "steer", wheelbase: float = 2.7,
                 max_steer_deg: float = 35.0, lookahead_s: float = 0.8, min_lookahead_m: float = 4.0) -> None:
        super().__init__()
        if output not in OUTPUTS:
            raise InputError("drive.network.output", f"one of {', '.join(OUTPUTS)}, got {output!r}")
        self.save_hyperparameters()
        chans = [in_channels, *[int(c) for c in channels]]
        self.encoder = nn.Sequential(*[_stage(a, b) for a, b in itertools.pairwise(chans)])
        with torch.no_grad():
            flat = self.encoder(self._shrink(torch.zeros(1, in_channels, height, width))).numel()
        self.image_fc = nn.Sequential(nn.Linear(flat, hidden), nn.ReLU(inplace=True), nn.Dropout(dropout))
        self.speed_fc = nn.Sequential(nn.Linear(1, 64), nn.ReLU(inplace=True), nn.Linear(64, 64), nn.ReLU(inplace=True))
        self.joint = nn.Sequential(nn.Linear(hidden + 64, hidden), nn.ReLU(inplace=True), nn.Dropout(dropout))
        self.branches = nn.ModuleList([nn.Sequential(nn.Linear(hidden, hidden // 2), nn.ReLU(inplace=True),
                                                     nn.Dropout(dropout), nn.Linear(hidden // 2, self.n_outputs))
                                       for _ in COMMANDS])
        self.speed_head = nn.Sequential(nn.Linear(hidden, 64), nn.ReLU(inplace=True), nn.Linear(64, 1))
        self._generator: torch.Generator | None = None
        self._inference_encoder = InferenceCopy(self.encoder)

    @property
    def n_outputs(self) -> int:
        """Outputs of a branch: (steer, target speed), or (the waypoints' 2 K coordinates, target speed)."""
        return 2 if self.hparams.get("output", "steer") == "steer" else 2 * len(WAYPOINT_ARCS) + 1

    def _control(self, out: torch.Tensor, speed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Steering and target speed / max speed of branch outputs ``(N, n_outputs)`` at ``speed`` (m/s)."""
        if self.n_outputs == 2:
            return out[:, 0], out[:, 1]
        hp = self.hparams
        steer = pure_pursuit(out[:, :-1], speed, float(hp.wheelbase), float(hp.max_steer_deg), float(hp.lookahead_s),
                             float(hp.min_lookahead_m))
        return steer, out[:, -1]

    def _shrink(self, images: torch.Tensor) -> torch.Tensor:
        """The camera images averaged over ``downsample`` x ``downsample`` pixels (what the encoder sees)."""
        k = int(self.hparams.get("downsample", 1))
        return F.avg_pool2d(images, k) if k > 1 else images

    @staticmethod
    def _normalize(images: torch.Tensor) -> torch.Tensor:
        """Local-contrast normalisation of shrunk float images."""
        return local_normalize(images)

    def _features(self, images: torch.Tensor, inference: bool = False) -> torch.Tensor:
        """The image features (N, hidden) of shrunk float images (0..255); ``inference``: through the encoder's
        folded copy (:mod:`topoloc.fast_inference`; the closed loop, without gradients)."""
        encoder = self._inference_encoder if inference else self.encoder
        return self.image_fc(torch.flatten(encoder(self._normalize(images)), 1))

    def _heads(self, images: torch.Tensor, speed: torch.Tensor, inference: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """All branches' outputs (N, commands, 2) and the speed prediction (N,) of shrunk float images (0..255)."""
        feat = self._features(images, inference)
        joint = self.joint(torch.cat([feat, self.speed_fc(speed[:, None] / self.hparams.max_speed)], dim=1))
        return torch.stack([b(joint) for b in self.branches], dim=1), self.speed_head(feat)[:, 0]

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """(steer, target speed m/s) ``(N, 2)`` of ``(N, C + 2, H, W)``: image, speed plane (m/s), command plane (index)."""
        c = int(self.hparams.in_channels)
        images, speed, command = inputs[:, :c].float(), inputs[:, c, 0, 0].float(), inputs[:, c + 1, 0, 0].long()
        out, _ = self._heads(self._shrink(images), speed)
        steer, target = self._control(out[torch.arange(len(out), device=out.device), command.clamp(0, len(COMMANDS) - 1)], speed)
        return torch.stack([steer, target * self.hparams.max_speed], dim=1)

    @torch.no_grad()
    def act(self, image: NDArray[np.uint8], speed: float, command: int) -> tuple[float, float]:
        """Steer and throttle for one camera image (H, W, C) uint8, the speed (m/s) and a command index."""
        eval_mode(self)
        x = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None].float()
        v = torch.tensor([float(speed)])
        out, _ = self._heads(self._shrink(x), v, inference=True)
        steer_t, target_t = self._control(out[:, int(command)], v)
        steer, target = float(steer_t[0]), float(target_t[0])
        throttle = self.hparams.speed_gain * (target * self.hparams.max_speed - float(speed))
        return float(np.clip(steer, -1.0, 1.0)), float(np.clip(throttle, -1.0, 1.0))

    # -- training ----------------------------------------------------------------------------------------
    def _outputs(self, x: torch.Tensor, speed: torch.Tensor, condition: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The commanded branch's output (N, n_outputs) and the speed prediction of a batch (``condition``: the commands)."""
        out, speed_pred = self._heads(x, speed)
        return out[torch.arange(len(out), device=out.device), condition], speed_pred

    def _step(self, batch: Any, stage: str) -> torch.Tensor:
        images, speed, condition, target = batch
        x = self._shrink(images.permute(0, 3, 1, 2).float())
        if stage == "train" and self.hparams.augment:
            if self._generator is None:
                self._generator = torch.Generator(device=x.device).manual_seed(int(self.hparams.seed))
            x = augment(x, self._generator, shift_px=0)
        chosen, speed_pred = self._outputs(x, speed, condition)
        steer, target_speed = self._control(chosen, speed)
        w = float(self.hparams.steer_weight)
        if self.n_outputs == 2:  # target: steer, target speed (, waypoints)
            steer_err = (steer - target[:, 0]) ** 2
        else:
            steer_err = ((chosen[:, :-1] - target[:, 2:]) ** 2).mean(dim=1)
        control = (w * steer_err + (1.0 - w) * (target_speed - target[:, 1]) ** 2).mean()
        speed_loss = F.mse_loss(speed_pred, speed / self.hparams.max_speed)
        loss = control + float(self.hparams.speed_weight) * speed_loss
        opts = {"on_epoch": True, "batch_size": len(x)}
        self.log(f"{stage}/loss", loss, prog_bar=True, on_step=stage == "train", **opts)
        self.log(f"{stage}/steer_mae", (steer - target[:, 0]).abs().mean(), on_step=False, **opts)
        self.log(f"{stage}/speed_mae", (target_speed - target[:, 1]).abs().mean() * self.hparams.max_speed, on_step=False,
                 **opts)
        return loss

    def training_step(self, batch: Any, batch_idx: int) -> torch.Tensor:
        return self._step(batch, "train")

    def validation_step(self, batch: Any, batch_idx: int) -> None:
        self._step(batch, "val")

    def configure_optimizers(self) -> Any:
        return torch.optim.Adam(self.parameters(), lr=self.hparams.lr, weight_decay=self.hparams.weight_decay)
