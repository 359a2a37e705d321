"""Topo-LP: the local-path controller of Cai & Wan (image + a top-down image of the path ahead, no discrete command).

The camera image goes through Topo-DLM's encoder (:class:`topoloc.drive.controller.TopoDLM`: averaged over
``downsample`` pixels, local-contrast normalised, ``channels`` stages, a layer of ``hidden`` units); the local-path
image (:mod:`topoloc.drive.local_path`, ``PATH_PX`` square, 0..255) through two strided convolutions (8 and 16
channels) and a layer of 64 units; the speed through Topo-DLM's speed encoder. A joint layer and **one** head give
(steer, target speed): the path says where to go, so there is no branch per command. Same losses as Topo-DLM.
With ``image_dropout`` (``drive.train.image_dropout``) that share of the training samples reaches the joint layer
with its image features zeroed, so the head must steer by the path and speed alone (the speed head still sees them).
With ``path_frame: aligned`` (``drive.network.path_frame``, a deviation from the paper) the path is told in the
vehicle's frame (:mod:`topoloc.drive.ground_alignment`), so the image need not tell where the vehicle stands on it.
With ``path_prior`` (``drive.network.path_prior``, the ``waypoints`` output only; a deviation from the paper) the
head gives a correction to the lane points: they are the local path's own points at the waypoint arcs plus the head's
output, so a path that bends hard turns the wheel hard before the network has learnt anything, and the image says
how far the vehicle is off the path (its offset from the teach drive, the localization's error along the path).
With ``path_form: move`` (:data:`topoloc.drive.local_path.PATH_FORMS`) it is told only the path's move
(:func:`topoloc.drive.local_path.move_path`: one turn, where it begins, how much, over how long): that is Topo-DLM with
``drive.network.dlm_command: move``, the local move with the turn's geometry (:func:`controller_class`).

``forward`` takes ``(N, C + 2, H, W)`` like Topo-DLM's, with the local-path plane
(:func:`topoloc.drive.local_path.path_plane`: the path image, then its points) in the top-left
``PATH_PX + 1`` x ``PATH_PX`` pixels of the last plane (in place of the command): the signature of the logged model.
:meth:`TopoLP.act` is the closed-loop call.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from topoloc.drive.controller import WAYPOINT_ARCS, WAYPOINT_SCALE_M, TopoDLM
from topoloc.drive.local_path import PATH_FORMS, PATH_PX, PLANE_POINTS
from topoloc.errors import InputError
from topoloc.place.network import eval_mode

PATH_FEATURES = 64
#: Frames of the local path (``drive.network.path_frame``): the localized vertex's (the paper's) or the vehicle's.
PATH_FRAMES = ("lane", "aligned")


class TopoLP(TopoDLM):
    """The local-path controller of the module docstring (Topo-DLM's encoders, a path encoder, one head)."""

    def __init__(self, image_dropout: float = 0.0, path_prior: bool = False, path_frame: str = "lane",
                 path_form: str = "path", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if path_frame not in PATH_FRAMES:
            raise InputError("drive.network.path_frame", f"one of {', '.join(PATH_FRAMES)}, not {path_frame!r}")
        if path_form not in PATH_FORMS:
            raise InputError("drive.network.dlm_command", f"told the path as one of {', '.join(PATH_FORMS)}, not {path_form!r}")
        if not 0.0 <= float(image_dropout) < 1.0:
            raise InputError("drive.train.image_dropout", f"must be in [0, 1), got {image_dropout}")
        if path_prior and self.hparams.output != "waypoints":
            raise InputError("drive.network.path_prior", "needs the waypoints output (drive.network.output), "
                             f"not {self.hparams.output}")
        if int(self.hparams.height) <= PATH_PX or int(self.hparams.width) < PATH_PX:
            raise InputError("place.image", f"Topo-LP needs images of at least {PATH_PX} x {PATH_PX + 1} pixels for its "
                             f"local-path plane, not {self.hparams.width} x {self.hparams.height}")
        self._image_generator: torch.Generator | None = None
        hidden, dropout = int(self.hparams.hidden), float(self.hparams.dropout)
        self.path_encoder = nn.Sequential(
            nn.Conv2d(1, 8, 3, 2, 1), nn.ReLU(inplace=True), nn.Conv2d(8, 16, 3, 2, 1), nn.ReLU(inplace=True),
            nn.Flatten(), nn.Linear(16 * (PATH_PX // 4) ** 2, PATH_FEATURES), nn.ReLU(inplace=True))
        self.joint = nn.Sequential(nn.Linear(hidden + 64 + PATH_FEATURES, hidden), nn.ReLU(inplace=True), nn.Dropout(dropout))
        self.branches = nn.ModuleList([nn.Sequential(nn.Linear(hidden, hidden // 2), nn.ReLU(inplace=True),
                                                     nn.Dropout(dropout), nn.Linear(hidden // 2, self.n_outputs))])

    def _lp_heads(self, images: torch.Tensor, speed: torch.Tensor, paths: torch.Tensor,
                  inference: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """The head's outputs ``(N, n_outputs)`` and the speed prediction of shrunk images and path planes
        (N, P + 1, P): :func:`topoloc.drive.local_path.path_plane`; ``inference`` as :meth:`TopoDLM._features` takes it."""
        feat = self._features(images, inference)
        path = self.path_encoder(paths[:, None, :PATH_PX].float() / 255.0)
        seen = feat
        p = float(self.hparams.image_dropout)
        if self.training and p > 0:  # whole samples without the image: the head must steer by the path too
            keep = torch.rand(len(feat), 1, device=feat.device, generator=self._dropout_generator(feat.device)) >= p
            seen = feat * keep
        joint = self.joint(torch.cat([seen, self.speed_fc(speed[:, None] / self.hparams.max_speed), path], dim=1))
        out = self.branches[0](joint)
        if self.hparams.get("path_prior", False):  # the head corrects the path's own lane points
            if paths.shape[1] <= PATH_PX:
                raise ValueError("a Topo-LP with path_prior is told the local-path plane (local_path.path_plane: the "
                                 "image and the path's points), not the path image alone")
            points = paths[:, PATH_PX, : 2 * PLANE_POINTS].float().reshape(len(paths), PLANE_POINTS, 2)
            prior = points[:, [int(a) - 1 for a in WAYPOINT_ARCS]].reshape(len(paths), -1) / WAYPOINT_SCALE_M
            out = out + torch.cat([prior, torch.zeros_like(out[:, -1:])], dim=1)
        return out, self.speed_head(feat)[:, 0]

    def _dropout_generator(self, device: torch.device) -> torch.Generator:
        if self._image_generator is None:
            self._image_generator = torch.Generator(device=device).manual_seed(int(self.hparams.seed) + 1)
        return self._image_generator

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """(steer, target speed m/s) ``(N, 2)`` of ``(N, C + 2, H, W)``: image, speed plane, path plane (module docstring)."""
        c = int(self.hparams.in_channels)
        speed = inputs[:, c, 0, 0].float()
        out, _ = self._lp_heads(self._shrink(inputs[:, :c].float()), speed, inputs[:, c + 1, : PATH_PX + 1, :PATH_PX])
        steer, target = self._control(out, speed)
        return torch.stack([steer, target * self.hparams.max_speed], dim=1)

    @torch.no_grad()
    def act(self, image: NDArray[np.uint8], speed: float, path: NDArray[np.uint8]) -> tuple[float, float]:  # type: ignore[override]
        """Steer and throttle for one camera image (H, W, C) uint8, the speed (m/s) and a local-path plane
        (:func:`topoloc.drive.local_path.path_plane`)."""
        eval_mode(self)
        x = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None].float()
        v = torch.tensor([float(speed)])
        out, _ = self._lp_heads(self._shrink(x), v, torch.from_numpy(path)[None], inference=True)
        steer_t, target_t = self._control(out, v)
        steer, target = float(steer_t[0]), float(target_t[0])
        throttle = self.hparams.speed_gain * (target * self.hparams.max_speed - float(speed))
        return float(np.clip(steer, -1.0, 1.0)), float(np.clip(throttle, -1.0, 1.0))

    def _outputs(self, x: torch.Tensor, speed: torch.Tensor, condition: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The head's output and speed prediction of a batch (``condition``: the path planes)."""
        return self._lp_heads(x, speed, condition)


#: The controllers ``train_controller`` trains and ``follow_route`` drives.
CONTROLLERS = ("dlm", "lp")
#: What Topo-DLM is told (``drive.network.dlm_command``): the paper's discrete command, or the move with its geometry.
DLM_COMMANDS = ("discrete", "move")


def controller_class(agent: str, dlm_command: str = "discrete") -> type[TopoDLM]:
    """The network of controller ``agent``: Topo-LP's for ``lp`` and for a Topo-DLM told the move (``dlm_command:
    move``: Topo-LP's network told the path's move, ``path_form: move``), the branched Topo-DLM for the discrete
    command."""
    if agent not in CONTROLLERS:
        raise InputError("controller", f"unknown controller {agent!r} (one of {', '.join(CONTROLLERS)})")
    if dlm_command not in DLM_COMMANDS:
        raise InputError("drive.network.dlm_command", f"one of {', '.join(DLM_COMMANDS)}, not {dlm_command!r}")
    return TopoLP if agent == "lp" or dlm_command == "move" else TopoDLM


def load_controller(path: str | Path, image_shape: tuple[int, int, int] | None = None,
                    where: str = "place.image") -> TopoDLM:
    """The controller of a ``train_controller`` checkpoint (a Topo-LP network when its hyperparameters say it was told
    a path, else the branched Topo-DLM), on the CPU, in eval mode.

    InputError naming the file when it is not one, or ``where`` when it was trained on images of another
    shape than ``image_shape`` (H, W, C).
    """
    try:
        hparams = torch.load(str(path), map_location="cpu", weights_only=False).get("hyper_parameters", {})
        cls = TopoLP if {"image_dropout", "path_frame"} & set(hparams) else TopoDLM
        model = cls.load_from_checkpoint(str(path), map_location="cpu")
    except (OSError, RuntimeError, KeyError, TypeError, AttributeError, pickle.UnpicklingError) as err:
        raise InputError(path, f"not a controller checkpoint ({err})") from err
    hp = model.hparams
    if image_shape is not None and (int(hp.height), int(hp.width), int(hp.in_channels)) != tuple(image_shape):
        raise InputError(where, f"the controller {path} was trained on {hp.width}x{hp.height}x{hp.in_channels} images, "
                         f"not {image_shape[1]}x{image_shape[0]}x{image_shape[2]}")
    return model.eval()


def told_path(model: Any) -> bool:
    """Whether ``model`` is told a local path (a Topo-LP network: Topo-LP, or Topo-DLM told the move), not a command."""
    return isinstance(model, TopoLP)


def path_frame(model: Any) -> str:
    """The frame of the local path controller ``model`` was trained on (``lane`` for a Topo-DLM and older Topo-LPs)."""
    return str(model.hparams.get("path_frame", "lane")) if hasattr(model, "hparams") else "lane"


def path_form(model: Any) -> str:
    """What of the path ``model`` is told: ``path``, or ``move`` (:func:`topoloc.drive.local_path.move_path`)."""
    return str(model.hparams.get("path_form", "path")) if hasattr(model, "hparams") else "path"
