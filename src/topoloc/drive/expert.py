"""The expert driver: pure pursuit on the lane centre, a speed profile, and noise injection for demonstrations.

* **Steering** (pure pursuit): the rear axle is projected on the lane; the target is the lane point
  ``max(min_lookahead_m, lookahead_s * v)`` further on; the steering angle that puts the rear axle on the
  circle through it is ``atan(2 L sin(alpha) / l)`` (``alpha`` the target's bearing off the heading, ``l``
  the lookahead, ``L`` the wheelbase).
* **Speed**: ``cruise_mps``, at most ``sqrt(lateral_accel_mps2 / curvature)`` in curves, and braking early
  enough (at ``decel_mps2``) to be at that speed when a curve begins; throttle ``speed_gain`` times the
  speed error.
* **Command**: the lane's navigation command at the vehicle's progress (it knows the route).
* **Noise injection** (Codevilla et al.): in about ``share`` of the steps a triangular steering offset of up to
  ``steer`` (random sign, ``duration_s`` long) is added to the *executed* steering; the recorded label stays
  the expert's own (corrective) steering, so the data shows how to come back to the lane.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from topoloc.drive.drive_route import DriveRoute
from topoloc.drive.lane_geometry import DENSE_M
from topoloc.drive.simulator import Control, VehicleSpec, VehicleState
from topoloc.errors import InputError


@dataclass(frozen=True)
class ExpertSettings:
    """``drive.expert`` in the config."""

    cruise_mps: float = 6.0
    lateral_accel_mps2: float = 2.0
    decel_mps2: float = 2.0
    lookahead_s: float = 0.8
    min_lookahead_m: float = 4.0
    speed_gain: float = 0.5

    @classmethod
    def from_conf(cls, expert: dict[str, Any]) -> ExpertSettings:
        """Settings of a validated ``drive.expert`` slice."""
        settings = cls(**{k: float(v) for k, v in expert.items()})
        if settings.cruise_mps <= 0:
            raise InputError("drive.expert.cruise_mps", f"must be positive, got {settings.cruise_mps}")
        return settings


def speed_profile(route: DriveRoute, settings: ExpertSettings, max_speed: float) -> NDArray[np.float64]:
    """The target speed at every lane sample (see the module docstring)."""
    curvature = np.abs(np.gradient(route.yaw, route.s, edge_order=1))
    curvature = gaussian_filter1d(curvature, 2.0 / DENSE_M, mode="nearest")
    limit = np.minimum(min(settings.cruise_mps, max_speed), np.sqrt(settings.lateral_accel_mps2 / np.maximum(curvature, 1e-6)))
    ds = np.diff(route.s)
    for i in range(len(limit) - 2, -1, -1):  # brake in time for the next curve
        limit[i] = min(limit[i], np.sqrt(limit[i + 1] ** 2 + 2.0 * settings.decel_mps2 * ds[i]))
    return np.maximum(limit, 1.0)


class Expert:
    """Pure pursuit and the speed profile on one route."""

    def __init__(self, route: DriveRoute, spec: VehicleSpec, settings: ExpertSettings) -> None:
        self.route, self.spec, self.settings = route, spec, settings
        self.speed = speed_profile(route, settings, spec.max_speed_mps)
        self.s_rear, self.last_target = 0.0, 0.0

    def reset(self) -> None:
        """Forget the progress of the last episode."""
        self.s_rear, self.last_target = 0.0, 0.0

    def target_speed(self, s: float) -> float:
        """The profile's speed at arc length ``s``."""
        return float(self.speed[self.route.index(s)])

    def control(self, state: VehicleState) -> Control:
        """The expert's control at ``state`` (its target speed is kept as ``last_target``)."""
        route, spec, cfg = self.route, self.spec, self.settings
        rear = np.array([state.x, state.y])
        self.s_rear, _, _ = route.project(rear, self.s_rear)
        look = max(cfg.min_lookahead_m, cfg.lookahead_s * state.v)
        target = route.point_ahead(self.s_rear + look)
        alpha = np.arctan2(target[1] - rear[1], target[0] - rear[0]) - state.yaw
        alpha = (alpha + np.pi) % (2 * np.pi) - np.pi
        delta = np.arctan2(2.0 * spec.wheelbase_m * np.sin(alpha), look)
        steer = float(np.clip(delta / np.radians(spec.max_steer_deg), -1.0, 1.0))
        centre_s = self.s_rear + 0.5 * spec.wheelbase_m
        self.last_target = self.target_speed(centre_s)
        throttle = float(np.clip(cfg.speed_gain * (self.last_target - state.v), -1.0, 1.0))
        return Control(steer, throttle)


@dataclass(frozen=True)
class NoiseSettings:
    """``drive.noise`` in the config: share of perturbed steps, perturbation length range, peak steering offset."""

    share: float = 0.15
    duration_s: tuple[float, float] = (0.5, 2.0)
    steer: float = 0.3

    @classmethod
    def from_conf(cls, noise: dict[str, Any]) -> NoiseSettings:
        """Settings of a validated ``drive.noise`` slice."""
        lo, hi = (float(v) for v in noise["duration_s"])
        if not 0 < lo <= hi:
            raise InputError("drive.noise.duration_s", f"needs 0 < min <= max, got {noise['duration_s']}")
        if not 0 <= float(noise["share"]) < 1:
            raise InputError("drive.noise.share", f"must be in [0, 1), got {noise['share']}")
        return cls(float(noise["share"]), (lo, hi), float(noise["steer"]))


class NoiseInjector:
    """Seeded triangular steering perturbations (see the module docstring), one :meth:`offset` per step."""

    def __init__(self, settings: NoiseSettings, control_hz: float, rng: np.random.Generator) -> None:
        self.settings, self.hz, self.rng = settings, float(control_hz), rng
        mean_steps = 0.5 * sum(settings.duration_s) * self.hz
        self.p_start = settings.share / max(mean_steps * (1.0 - settings.share), 1e-9)
        self.left, self.length, self.amplitude = 0, 0, 0.0

    def offset(self) -> float:
        """The steering offset of this step (0 outside a perturbation)."""
        if self.left == 0:
            if self.settings.share <= 0 or self.rng.random() >= self.p_start:
                return 0.0
            self.length = max(2, round(self.rng.uniform(*self.settings.duration_s) * self.hz))
            self.left = self.length
            self.amplitude = float(self.rng.choice([-1.0, 1.0]) * self.rng.uniform(0.5, 1.0) * self.settings.steer)
        tau = (self.length - self.left + 0.5) / self.length
        self.left -= 1
        return self.amplitude * (1.0 - abs(2.0 * tau - 1.0))
