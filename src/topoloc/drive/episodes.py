"""Teach and repeat in closed loop: one repeat drive (:func:`run_episode`) of an agent (:mod:`topoloc.drive.agents`)
told where it is by a localization on the topometric map (:mod:`topoloc.drive.localization_adapters`), and the teach
drive it is held to.

* **Unsure localization**: when no answer of the last ``lost_steps`` steps had a confidence of at least
  ``place.localize.threshold`` the agents slow down to ``slow_mps`` (as the paper does while relocalizing).
* **Speed limit from the map**: the teach drive's target speed at each map vertex, recorded from the expert's teach
  drive of the route (:func:`teach_controls`; the replay agent drives by it); with ``teach_speed_ahead_m`` every agent
  stays under the lowest of them from its localized vertex to that far ahead (:func:`speed_limit_ahead`). The
  controllers predict their target speed from the image, and at 6 m/s a 5 m radius junction turn is taken too fast;
  the map knows the teach drive slowed there.

:func:`run_episode` drives one repeat and returns its outcome, path, progress and speed per step, localization errors,
timing and, when asked, frames for a strip or a movie of the drive.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.demonstrations import as_input
from topoloc.drive.expert import Expert
from topoloc.drive.simulator import RUNNING, Control, Simulator
from topoloc.place.topometric_map import COMMANDS, TopometricMap


def speed_limit_ahead(speed: NDArray[np.float64], lane_s: NDArray[np.float64], ahead_m: float) -> NDArray[np.float64]:
    """Per vertex, the lowest ``speed`` of the vertices from it to ``ahead_m`` further along the lane (``lane_s``, sorted)."""
    end = np.searchsorted(lane_s, lane_s + ahead_m, side="right")
    return np.array([speed[k:max(k + 1, e)].min() for k, e in enumerate(end)], float)


def teach_controls(sim: Simulator, expert: Expert, condition: str, seed: int,
                   lane_s: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The expert's teach drive (no noise, no images needed): its steering and target speed at every map vertex."""
    sim.reset(condition, seed)
    expert.reset()
    s, steer, speed, status = [], [], [], RUNNING
    while status == RUNNING:
        control = expert.control(sim.state)
        s.append(sim.s)
        steer.append(control.steer)
        speed.append(expert.last_target)
        _, status = sim.step(control, render=False)
    order = np.maximum.accumulate(np.asarray(s))
    return np.interp(lane_s, order, steer), np.interp(lane_s, order, speed)


@dataclass
class Episode:
    """One repeat drive: outcome, steps, progress (m), path of the vehicle, localization errors, timing, frames; per
    step its progress ``s`` along the lane (m), ``speed`` (m/s) and heading ``yaw`` (rad, like ``xy`` one more than
    the steps: the start and after each step), and per step the localized ``vertex`` and the ``steer`` commanded;
    ``movie``: every few steps a :class:`MovieFrame`."""

    outcome: str
    steps: int
    progress_m: float
    xy: NDArray[np.float64]
    loc_error_m: NDArray[np.float64]
    slow_steps: int
    seconds: float
    mean_abs_lateral_m: float
    frames: list[tuple[NDArray[np.uint8], str]] = field(default_factory=list)
    s: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    speed: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    movie: list[MovieFrame] = field(default_factory=list)
    yaw: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    vertex: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    steer: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class MovieFrame:
    """One frame of a drive's movie: the camera image, the vehicle's position and heading, the localized vertex, the
    command there, the steering and speed, and the time (s)."""

    image: NDArray[np.uint8]
    xy: NDArray[np.float64]
    yaw: float
    vertex: int
    command: str
    steer: float
    speed: float
    t: float


def run_episode(sim: Simulator, agent: Any, localization: Any, topo: TopometricMap, condition: str, seed: int,
                conf: dict[str, Any], strip_frames: int = 0, speed_limit: NDArray[np.float64] | None = None,
                movie_every: int = 0) -> Episode:
    """Drive one repeat of ``sim``'s route under ``condition`` (``conf``: the ``drive`` and ``place`` slices;
    ``speed_limit``: m/s per map vertex, :func:`speed_limit_ahead`; ``movie_every``: a movie frame every that many
    steps, none at 0)."""
    drive, place = conf["drive"], conf["place"]
    follow, noise = drive["follow"], place["odometry_noise"]
    rng = np.random.default_rng([seed, 53])
    lateral = float(rng.uniform(-1, 1) * follow["start_lateral_m"])
    yaw = float(rng.uniform(-1, 1) * follow["start_yaw_deg"])
    scale = 1.0 + float(rng.normal(0.0, float(noise["scale_error"])))
    color = bool(place["image"]["color"])
    threshold, lost, slow = float(place["localize"]["threshold"]), int(follow["lost_steps"]), float(follow["slow_mps"])
    gain = float(drive["expert"]["speed_gain"])
    obs = sim.reset(condition, seed, lateral, yaw)
    localization.start(rng)
    expected = sim.route.length_m / float(drive["expert"]["cruise_mps"]) * sim.spec.control_hz  # steps at cruise speed
    every = max(1, int(expected // strip_frames)) if strip_frames else 0
    xy, errors, frames, since_sure, slow_steps, lat = [sim.centre], [], [], 0, 0, []
    s_trace, speed_trace, movie = [sim.s], [sim.state.v], []
    yaw_trace, vertex_trace, steer_trace = [float(sim.state.yaw)], [], []
    previous, status = sim.centre, RUNNING
    started = time.perf_counter()
    while status == RUNNING:
        image = as_input(obs.image, color)
        here = sim.centre
        true_ds = float(np.hypot(*(here - previous)))
        previous = here
        ds = max(0.0, true_ds * scale + float(rng.normal(0.0, float(noise["distance_noise"]) * true_ds)))
        vertex, confidence = localization.update(image, ds, sim)
        errors.append(float(np.hypot(*(topo.gt_xy[vertex] - here))))
        since_sure = 0 if confidence >= threshold else since_sure + 1
        control = agent.act(image, obs.speed, vertex)
        limit = float(speed_limit[vertex]) if speed_limit is not None else np.inf
        if since_sure >= lost:
            slow_steps += 1
            limit = min(limit, slow)
        if limit < np.inf:
            control = Control(control.steer, min(control.throttle, gain * (limit - obs.speed)))
        if every and sim.t % every == 0 and len(frames) < strip_frames:
            frames.append((obs.image, (f"t={sim.t / sim.spec.control_hz:.0f}s {COMMANDS[int(topo.command[vertex])]} "
                                      f"{control.steer:+.2f}")))
        if movie_every and sim.t % movie_every == 0:
            movie.append(MovieFrame(obs.image, sim.centre, float(sim.state.yaw), int(vertex),
                                    COMMANDS[int(topo.command[vertex])], float(control.steer), float(obs.speed),
                                    sim.t / sim.spec.control_hz))
        vertex_trace.append(int(vertex))
        steer_trace.append(float(control.steer))
        obs, status = sim.step(control)
        xy.append(sim.centre)
        yaw_trace.append(float(sim.state.yaw))
        s_trace.append(sim.s)
        speed_trace.append(sim.state.v)
        lat.append(abs(sim.lateral))
        if obs is None:
            break
    seconds = time.perf_counter() - started
    return Episode(status, sim.t, sim.s, np.asarray(xy), np.asarray(errors), slow_steps, seconds,
                   float(np.mean(lat)) if lat else 0.0, frames, np.asarray(s_trace), np.asarray(speed_trace), movie,
                   np.asarray(yaw_trace), np.asarray(vertex_trace, np.int64), np.asarray(steer_trace))
