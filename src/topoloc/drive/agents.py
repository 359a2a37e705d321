"""The agents at the wheel of a repeat drive, each told the vertex it is localized at on the map:
:class:`DLMAgent` (Topo-DLM: the image, the speed and the vertex's command), :class:`LPAgent` (Topo-LP: the image,
the speed and the local path of the map from the vertex) and :class:`ReplayAgent` (the paper's baseline: the
steering the expert used at that vertex in the teach drive, and its target speed there); :class:`ExpertAgent` (the
expert itself, which sees the true state: the ceiling of the junction benchmark)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.controller import AGENT_NAMES
from topoloc.drive.expert import Expert
from topoloc.drive.local_path import map_path, path_plane
from topoloc.drive.simulator import Control, Simulator
from topoloc.place.topometric_map import TopometricMap


class DLMAgent:
    """Topo-DLM driven by the command of the localized vertex."""

    name = "Topo-DLM"

    def __init__(self, model: Any, topo: TopometricMap) -> None:
        self.model, self.topo = model, topo

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        return Control(*self.model.act(image, speed, int(self.topo.command[vertex])))


class LPAgent:
    """Topo-LP driven by the local path of the localized vertex (:func:`topoloc.drive.local_path.map_path`)."""

    name = "Topo-LP"

    def __init__(self, model: Any, topo: TopometricMap) -> None:
        self.model, self.topo = model, topo
        self._paths: dict[int, NDArray[np.float32]] = {}

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        if vertex not in self._paths:
            self._paths[vertex] = path_plane(map_path(self.topo.xy, vertex))
        return Control(*self.model.act(image, speed, self._paths[vertex]))


class ReplayAgent:
    """The teach drive's steering and speed at the localized vertex (the paper's replay baseline)."""

    name = "replay"

    def __init__(self, steer: NDArray[np.float64], speed: NDArray[np.float64], gain: float) -> None:
        self.steer, self.speed, self.gain = steer, speed, gain

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        return Control(float(self.steer[vertex]), float(np.clip(self.gain * (self.speed[vertex] - speed), -1, 1)))


class ExpertAgent:
    """The expert driving ``sim``'s route from the vehicle's true state (it ignores the image and the vertex)."""

    name = "expert"

    def __init__(self, expert: Expert, sim: Simulator) -> None:
        self.expert, self.sim = expert, sim
        expert.reset()

    def act(self, image: NDArray[np.uint8], speed: float, vertex: int) -> Control:
        return self.expert.control(self.sim.state)


def method_name(agent: str, localization: str) -> str:
    """Table row of an agent with a localization."""
    return f"{AGENT_NAMES[agent]} ({'ground truth' if localization == 'ground_truth' else localization})"
