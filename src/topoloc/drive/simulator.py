"""A closed-loop driving simulator in the rendered streets: a kinematic vehicle on a route's lane.

* **Vehicle** (:func:`step_vehicle`): the kinematic bicycle model at the rear axle, ``wheelbase_m`` long;
  the steering angle follows the command at most ``max_steer_rate_deg_s`` and within ``max_steer_deg``;
  throttle accelerates by up to ``max_accel_mps2``, negative throttle brakes by up to ``max_brake_mps2``;
  the speed stays within ``0..max_speed_mps``. One step is ``1 / control_hz`` seconds (Euler integration).
  A control is ``steer`` in [-1, 1] (+1: full left, counter-clockwise) and ``throttle`` in [-1, 1].
* **Camera**: at every step the renderer of :mod:`topoloc.render` draws the camera image at the vehicle's
  true pose (the middle of the wheelbase, looking along its heading) under the episode's condition.
* **Episode end** (judged at the middle of the wheelbase, on the rasters of :class:`~topoloc.drive.drive_route.DriveRoute`):
  ``success`` when the progress along the lane is within ``goal_m`` of its end; ``off_road`` off every
  carriageway; ``wrong_road`` on a carriageway that is not the route's (a wrong turn at an intersection);
  ``reversed`` when the heading is more than ``reversed_deg`` off the lane's; ``timeout`` after the time the
  lane takes at ``timeout_speed_mps`` (plus 10 s).

Everything is deterministic for a seed: the dynamics have no noise, the renderer's noise and rain depend on
(seed, step), and the start offsets are the caller's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.drive_route import DriveRoute
from topoloc.errors import InputError
from topoloc.render.conditions import get_condition
from topoloc.render.renderer import Renderer
from topoloc.render.rig import StereoRig
from topoloc.render.scene import Scene

RUNNING, SUCCESS, OFF_ROAD, WRONG_ROAD, REVERSED, TIMEOUT = "running", "success", "off_road", "wrong_road", "reversed", "timeout"
OUTCOMES = (SUCCESS, OFF_ROAD, WRONG_ROAD, REVERSED, TIMEOUT)


@dataclass(frozen=True)
class VehicleSpec:
    """The vehicle's limits and the simulator's rules (``drive.vehicle`` and ``drive.episode`` in the config)."""

    wheelbase_m: float = 2.7
    max_steer_deg: float = 35.0
    max_steer_rate_deg_s: float = 120.0
    max_accel_mps2: float = 3.0
    max_brake_mps2: float = 6.0
    max_speed_mps: float = 12.0
    control_hz: float = 10.0
    goal_m: float = 3.0
    reversed_deg: float = 120.0
    timeout_speed_mps: float = 2.0

    @classmethod
    def from_conf(cls, drive: dict[str, Any]) -> VehicleSpec:
        """The spec of a validated ``drive`` config slice."""
        spec = cls(**{k: float(v) for k, v in {**drive["vehicle"], **drive["episode"]}.items()})
        for key in ("wheelbase_m", "max_steer_deg", "max_speed_mps", "control_hz"):
            if getattr(spec, key) <= 0:
                raise InputError(f"drive.vehicle.{key}", f"must be positive, got {getattr(spec, key)}")
        return spec

    @property
    def dt(self) -> float:
        """Seconds per control step."""
        return 1.0 / self.control_hz


class Control(NamedTuple):
    """Steering (+1 full left) and throttle (negative: brake), both in [-1, 1]."""

    steer: float
    throttle: float


@dataclass(frozen=True)
class VehicleState:
    """Rear-axle position ``x``, ``y`` (map metres), heading ``yaw`` (radians from east), speed ``v`` (m/s), steering
    angle ``delta`` (radians, + left)."""

    x: float
    y: float
    yaw: float
    v: float
    delta: float = 0.0

    def centre(self, spec: VehicleSpec) -> NDArray[np.float64]:
        """The middle of the wheelbase (camera position and the point the episode is judged at)."""
        h = 0.5 * spec.wheelbase_m
        return np.array([self.x + h * np.cos(self.yaw), self.y + h * np.sin(self.yaw)])


def step_vehicle(state: VehicleState, control: Control, spec: VehicleSpec) -> VehicleState:
    """One step of the kinematic bicycle model (see the module docstring)."""
    dt = spec.dt
    max_delta = np.radians(spec.max_steer_deg)
    target = float(np.clip(control.steer, -1.0, 1.0)) * max_delta
    rate = np.radians(spec.max_steer_rate_deg_s) * dt
    delta = float(np.clip(state.delta + np.clip(target - state.delta, -rate, rate), -max_delta, max_delta))
    throttle = float(np.clip(control.throttle, -1.0, 1.0))
    accel = throttle * (spec.max_accel_mps2 if throttle >= 0 else spec.max_brake_mps2)
    v = float(np.clip(state.v + accel * dt, 0.0, spec.max_speed_mps))
    mean_v = 0.5 * (state.v + v)
    yaw = state.yaw + mean_v / spec.wheelbase_m * np.tan(delta) * dt
    mid = 0.5 * (state.yaw + yaw)
    return VehicleState(state.x + mean_v * np.cos(mid) * dt, state.y + mean_v * np.sin(mid) * dt, float(yaw), v, delta)


@dataclass(frozen=True)
class Observation:
    """What the vehicle sees after a step: the camera ``image`` (H, W, 3) BGR, its ``speed`` (m/s), the ``step``."""

    image: NDArray[np.uint8]
    speed: float
    step: int


class Simulator:
    """Episodes on one route (:meth:`reset`, then :meth:`step` until the status is not ``running``)."""

    def __init__(self, route: DriveRoute, scene: Scene, rig: StereoRig, spec: VehicleSpec, view_distance_m: float) -> None:
        self.route, self.scene, self.rig, self.spec, self.view = route, scene, rig, spec, float(view_distance_m)
        self._renderers: dict[tuple[str, int], Renderer] = {}
        self.max_steps = int(np.ceil(route.length_m / spec.timeout_speed_mps * spec.control_hz)) + int(10 * spec.control_hz)

    def renderer(self, condition: str, seed: int) -> Renderer:
        """The renderer of a condition and seed (built once)."""
        key = (condition, int(seed))
        if key not in self._renderers:
            self._renderers[key] = Renderer(self.scene, self.rig, get_condition(condition, "drive.condition"), int(seed),
                                            self.view)
        return self._renderers[key]

    def reset(self, condition: str, seed: int, lateral_m: float = 0.0, yaw_deg: float = 0.0, speed: float = 0.0,
              start_s: float = 0.0) -> Observation:
        """Start at arc length ``start_s`` of the lane, ``lateral_m`` to its right, ``yaw_deg`` left of its heading."""
        route, spec = self.route, self.spec
        k = route.index(start_s)
        yaw = float(route.yaw[k]) + np.radians(yaw_deg)
        centre = route.xy[k] + lateral_m * np.array([np.sin(route.yaw[k]), -np.cos(route.yaw[k])])
        h = 0.5 * spec.wheelbase_m
        self.state = VehicleState(centre[0] - h * np.cos(yaw), centre[1] - h * np.sin(yaw), yaw, float(speed))
        self.condition, self.seed, self.t = condition, int(seed), 0
        self.s, self.lateral = float(route.s[k]), float(lateral_m)
        self.status = RUNNING
        self._render = self.renderer(condition, seed)
        return self.observe()

    def observe(self) -> Observation:
        """The camera image and speed at the current state."""
        image = self._render.render(self.state.centre(self.spec), self.state.yaw, self.t)
        return Observation(image, self.state.v, self.t)

    @property
    def centre(self) -> NDArray[np.float64]:
        """The vehicle's middle point on the map."""
        return self.state.centre(self.spec)

    def judge(self) -> str:
        """The status of the current state (see the module docstring); updates the progress ``s`` and ``lateral``."""
        route, spec = self.route, self.spec
        xy = self.centre
        self.s, self.lateral, lane_yaw = route.project(xy, self.s)
        if not route.on_drivable(xy):
            return OFF_ROAD
        if not route.on_corridor(xy):
            return WRONG_ROAD
        off = abs((self.state.yaw - lane_yaw + np.pi) % (2 * np.pi) - np.pi)
        if off > np.radians(spec.reversed_deg):
            return REVERSED
        if self.s >= route.length_m - spec.goal_m:
            return SUCCESS
        if self.t >= self.max_steps:
            return TIMEOUT
        return RUNNING

    def step(self, control: Control, render: bool = True) -> tuple[Observation | None, str]:
        """Apply ``control`` for one step; the new observation (None without ``render`` or once ended) and status."""
        if self.status != RUNNING:
            raise RuntimeError(f"the episode has ended ({self.status}); call reset")
        self.state = step_vehicle(self.state, control, self.spec)
        self.t += 1
        self.status = self.judge()
        if self.status != RUNNING or not render:
            return None, self.status
        return self.observe(), self.status
