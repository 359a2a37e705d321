"""The agents at the wheel of a repeat drive, each told the vertex it is localized at on the map:
:class:`DLMAgent` (the discrete Topo-DLM: the image, the speed and the vertex's command), :class:`LPAgent` (Topo-LP,
and Topo-DLM told the move: the image, the speed and the local path of the map from the vertex, or its move;
:func:`controller_agent` picks the one a trained controller needs) and :class:`ReplayAgent` (the paper's baseline: the
steering the expert used at that vertex in the teach drive, and its target speed there); :class:`ExpertAgent` (the
expert itself, which sees the true state: the ceiling of the junction benchmark)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.controller import AGENT_NAMES
from topoloc.drive.demonstrations import as_input
from topoloc.drive.expert import Expert
from topoloc.drive.ground_alignment import GroundAligner, PoseTracker
from topoloc.drive.local_path import aligned_path, chain_frame, map_path, path_plane
from topoloc.drive.simulator import Control, Simulator
from topoloc.drive.topo_lp import path_form, path_frame, told_path
from topoloc.place.topometric_map import TopometricMap


class DLMAgent:
    """Topo-DLM driven by the command of the localized vertex."""

    def __init__(self, model: Any, topo: TopometricMap) -> None:
        self.model, self.topo = model, topo

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        return Control(*self.model.act(image, speed, int(self.topo.command[vertex])))


class TeachImages:
    """The controller camera's teach drive at the vertices of ``topo``: the image it took at each vertex's pose (its
    true position, heading along the chord to 2 m on, as :func:`topoloc.drive.local_path.chain_frame` takes it) under
    the teach ``condition``, rendered once per vertex."""

    def __init__(self, sim: Simulator, topo: TopometricMap, condition: str, seed: int, color: bool) -> None:
        self.sim, self.topo, self.color = sim, topo, bool(color)
        self.renderer = sim.renderer(condition, int(seed))
        self._images: dict[int, NDArray[np.uint8]] = {}

    def __call__(self, vertex: int) -> NDArray[np.uint8]:
        if vertex not in self._images:
            at, yaw = chain_frame(self.topo.gt_xy, vertex)
            self._images[vertex] = as_input(self.renderer.render(at, yaw, 0), self.color)
        return self._images[vertex]


class LPAgent:
    """Topo-LP driven by the local path of the localized vertex: in the vertex's frame
    (:func:`topoloc.drive.local_path.map_path`), or, for a Topo-LP trained with ``path_frame: aligned``, in the
    vehicle's frame as a :class:`topoloc.drive.ground_alignment.PoseTracker` on the ``teach`` images estimates it
    (:func:`topoloc.drive.local_path.aligned_path`); told in the controller's ``path_form`` (Topo-DLM told the move:
    the path's :func:`topoloc.drive.local_path.move_path`)."""

    def __init__(self, model: Any, topo: TopometricMap, teach: TeachImages | None = None) -> None:
        self.model, self.topo = model, topo
        self._paths: dict[int, NDArray[np.float32]] = {}
        self.form = path_form(model)
        self.tracker: PoseTracker | None = None
        if path_frame(model) == "aligned":
            if teach is None:
                raise ValueError("a Topo-LP trained with path_frame: aligned needs the teach drive's images")
            self.tracker = PoseTracker(GroundAligner(teach.sim.rig), topo.xy, teach, teach.sim.spec)
        self._last: Control | None = None

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        if self.tracker is not None:
            state = self.tracker.update(image, speed, vertex, self._last)
            plane = path_plane(aligned_path(self.topo.xy, self.tracker.vertex, state.centre(self.tracker.spec), state.yaw),
                               self.form)
        else:
            if vertex not in self._paths:
                self._paths[vertex] = path_plane(map_path(self.topo.xy, vertex), self.form)
            plane = self._paths[vertex]
        self._last = Control(*self.model.act(image, speed, plane))
        return self._last


def controller_agent(model: Any, topo: TopometricMap, teach: TeachImages | None = None) -> DLMAgent | LPAgent:
    """The agent that drives trained controller ``model`` on ``topo``: :class:`LPAgent` for a controller told a path
    (Topo-LP, Topo-DLM told the move), :class:`DLMAgent` for the discrete Topo-DLM."""
    return LPAgent(model, topo, teach) if told_path(model) else DLMAgent(model, topo)


class ReplayAgent:
    """The teach drive's steering and speed at the localized vertex (the paper's replay baseline)."""

    def __init__(self, steer: NDArray[np.float64], speed: NDArray[np.float64], gain: float) -> None:
        self.steer, self.speed, self.gain = steer, speed, gain

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        return Control(float(self.steer[vertex]), float(np.clip(self.gain * (self.speed[vertex] - speed), -1, 1)))


class ExpertAgent:
    """The expert driving ``sim``'s route from the vehicle's true state (it ignores the image and the vertex)."""

    def __init__(self, expert: Expert, sim: Simulator) -> None:
        self.expert, self.sim = expert, sim
        expert.reset()

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        return self.expert.control(self.sim.state)


def method_name(agent: str, localization: str) -> str:
    """Table row of an agent with a localization."""
    return f"{AGENT_NAMES[agent]} ({'ground truth' if localization == 'ground_truth' else localization})"
