"""Teach and repeat in closed loop: agents drive the teach route under another condition, told where they are
by a localization on the topometric map.

* **Localization** answers, every step, the map vertex the vehicle is at. :class:`GroundTruth` reads it off
  the vehicle's true progress along the lane; :class:`PlaceLocalization` runs a place localizer of the
  registry (:mod:`topoloc.localizers`: ``place_loop``, ``place_filter``, ``place_odometry``) on the step's
  image (its place window: the place images' camera), scored by the retrieval network against the map's embeddings, and on the odometry distance (the
  true distance with the noise model of ``place.odometry_noise``: a scale error per drive and white noise).
  It is *unsure* when no answer of the last ``lost_steps`` steps had a confidence of at least
  ``place.localize.threshold``; the agents then slow down to ``slow_mps`` (as the paper does while relocalizing).
* **Speed limit from the map**: the teach drive's target speed at each map vertex, recorded from the expert's teach
  drive of the route (the replay agent drives by it); with ``teach_speed_ahead_m`` every agent stays under the lowest
  of them from its localized vertex to that far ahead (:func:`speed_limit_ahead`). The controllers predict their
  target speed from the image, and at 6 m/s a 5 m radius junction turn is taken too fast; the map knows the teach
  drive slowed there.
* **Agents**: :class:`DLMAgent` (Topo-DLM: the image, the speed and the vertex's command), :class:`LPAgent`
  (Topo-LP: the image, the speed and the local path of the map from the vertex) and
  :class:`ReplayAgent` (the paper's baseline: the steering the expert used at that vertex in the teach drive,
  and its target speed there).

:func:`run_episode` drives one repeat and returns its outcome, path, localization errors and timing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.demonstrations import as_input
from topoloc.drive.expert import Expert
from topoloc.drive.drive_route import DriveRoute
from topoloc.drive.local_path import map_path, path_plane
from topoloc.drive.simulator import RUNNING, Control, Simulator
from topoloc.errors import InputError
from topoloc.localizer import Localizer
from topoloc.place.localize import Frame, Scorer
from topoloc.place.topometric_map import COMMANDS, TopometricMap


def vertex_lane_s(route: DriveRoute, topo: TopometricMap) -> NDArray[np.float64]:
    """Arc length along the lane of every map vertex (ground-truth positions, projected in order).

    Vertices further along the map than the lane is long (a map of the whole teach route, a lane cut to its first
    metres) are at the lane's end: a route that later comes back past the cut part is not projected onto it.
    InputError when the map's vertices do not follow the route (a map of another route or region).
    """
    out, s, dist = np.full(len(topo), route.length_m), 0.0, []
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(topo.gt_xy, axis=0).T))])
    for k, xy in enumerate(topo.gt_xy):
        if along[k] > route.length_m + 10.0:
            break
        s, lateral, _ = route.project(xy, s, 5.0, 10.0)
        out[k] = s
        if s < route.length_m - 1.0:
            dist.append(abs(lateral))
    if not dist or float(np.median(dist)) > 2.5:
        raise InputError("map", "the topometric map's vertices do not follow the teach route of this config "
                         "(a map of another route or region)")
    return np.maximum.accumulate(out)


@dataclass
class RepeatRoute:
    """One evaluation route: the lane from ``start_m`` of the teach route, the map of its own stretch of the teach
    drive (its first vertex at the start) and each vertex's arc length along the lane."""

    start_m: float
    route: DriveRoute
    topo: TopometricMap
    lane_s: NDArray[np.float64]


def route_starts(teach_m: float, length_m: float | None, routes: int) -> list[float]:
    """Where ``routes`` evaluation routes of ``length_m`` (None: the whole teach route) start on a teach route of
    ``teach_m``: evenly from its start to ``length_m`` before its end. InputError naming ``drive.follow.routes`` when
    several routes would all be the same."""
    if routes < 1:
        raise InputError("drive.follow.routes", f"must be at least 1, got {routes}")
    room = teach_m - (teach_m if length_m is None else min(float(length_m), teach_m))
    if routes > 1 and room < 1.0:
        raise InputError("drive.follow.routes", f"{routes} routes need drive.follow.length_m shorter than the "
                         f"{teach_m:.0f} m teach route (it is {length_m})")
    return [float(v) for v in np.linspace(0.0, room, routes)]


def repeat_routes(teach: DriveRoute, topo: TopometricMap, length_m: float | None, routes: int) -> list[RepeatRoute]:
    """The evaluation routes of ``drive.follow`` (:func:`route_starts`) on the teach route ``teach`` and its map."""
    lane_s = vertex_lane_s(teach, topo)
    out = []
    for start in route_starts(teach.length_m, length_m, routes):
        route = teach.part(start, teach.length_m - start if length_m is None else float(length_m))
        start = float(teach.s[np.searchsorted(teach.s, start, side="left")])  # the part's first lane sample
        lo = int(np.searchsorted(lane_s, start, side="left"))
        hi = int(np.searchsorted(lane_s, start + route.length_m, side="right"))
        if hi - lo < 2:
            raise InputError("map", f"the topometric map has no vertices on the teach route from {start:.0f} m "
                             f"to {start + route.length_m:.0f} m")
        out.append(RepeatRoute(start, route, topo.part(lo, hi), lane_s[lo:hi] - start))
    return out


class OnlineScorer(Scorer):
    """Retrieval scores of the images seen so far (embedded one per step) against the map's vertices."""

    def __init__(self, model: Any, vertices: NDArray[np.float32]) -> None:
        self.model, self.vertices, self.queries = model, vertices, []

    def add(self, image: NDArray[np.uint8]) -> int:
        """Embed the next image; its frame index."""
        self.queries.append(self.model.embed(image[None])[0])
        return len(self.queries) - 1

    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return np.asarray(self.model.same_place(self.queries[t], self.vertices[idx]), float)

    def matrix(self) -> NDArray[np.float64]:
        return self.model.score_matrix(np.stack(self.queries), self.vertices)

    def row(self, t: int) -> NDArray[np.float64]:
        return np.asarray(self.model.score_matrix(self.queries[t][None], self.vertices)[0], float)


class Localization(Protocol):
    """Where the vehicle is on the map, one step at a time."""

    name: str

    def start(self, rng: np.random.Generator) -> None: ...

    def update(self, image: NDArray[np.uint8], ds: float, sim: Simulator) -> tuple[int, float]:
        """The vertex after this step and its confidence."""
        ...


class GroundTruth:
    """The vertex at the vehicle's true progress along the lane (always sure)."""

    name = "ground_truth"

    def __init__(self, lane_s: NDArray[np.float64]) -> None:
        self.lane_s = lane_s

    def start(self, rng: np.random.Generator) -> None:
        """Nothing to forget."""

    def update(self, image: NDArray[np.uint8], ds: float, sim: Simulator) -> tuple[int, float]:
        i = int(np.clip(np.searchsorted(self.lane_s, sim.s), 0, len(self.lane_s) - 1))
        if i > 0 and sim.s - self.lane_s[i - 1] < self.lane_s[i] - sim.s:
            i -= 1
        return i, 1.0


class PlaceLocalization:
    """A place localizer of the registry on the map, fed the ``window`` (rows, columns) of the step's image that is the
    place images' camera (:func:`topoloc.drive.routes.place_window`) and the odometry distance."""

    def __init__(self, localizer: Localizer, topo: TopometricMap, model: Any, conf: dict[str, Any],
                 window: tuple[slice, slice]) -> None:
        if model.hparams.embedding_dim != topo.embedding.shape[1]:
            raise InputError("map", f"the topometric map holds {topo.embedding.shape[1]}-d embeddings; the retrieval "
                             f"model gives {model.hparams.embedding_dim}-d ones (rebuild the map with this model)")
        self.localizer, self.topo, self.model, self.conf, self.window = localizer, topo, model, conf, window
        self.name = localizer.name

    def start(self, rng: np.random.Generator) -> None:
        self.localizer.reset(self.topo, self.conf)
        self.scorer = OnlineScorer(self.model, self.topo.embedding)

    def update(self, image: NDArray[np.uint8], ds: float, sim: Simulator) -> tuple[int, float]:
        t = self.scorer.add(image[self.window])
        answer = self.localizer.update(Frame(float(ds), t, self.scorer))
        return int(answer.state), float(answer.confidence)


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
    """One repeat drive: outcome, steps, progress (m), path of the vehicle, localization errors, timing, frames."""

    outcome: str
    steps: int
    progress_m: float
    xy: NDArray[np.float64]
    loc_error_m: NDArray[np.float64]
    slow_steps: int
    seconds: float
    mean_abs_lateral_m: float
    frames: list[tuple[NDArray[np.uint8], str]] = field(default_factory=list)


def run_episode(sim: Simulator, agent: Any, localization: Any, topo: TopometricMap, condition: str, seed: int,
                conf: dict[str, Any], strip_frames: int = 0, speed_limit: NDArray[np.float64] | None = None) -> Episode:
    """Drive one repeat of ``sim``'s route under ``condition`` (``conf``: the ``drive`` and ``place`` slices;
    ``speed_limit``: m/s per map vertex, :func:`speed_limit_ahead`)."""
    drive, place = conf["drive"], conf["place"]
    follow, noise = drive["follow"], place["odometry_noise"]
    rng = np.random.default_rng([seed, 53])
    lateral = float(rng.uniform(-1, 1) * follow["start_lateral_m"])
    yaw = float(rng.uniform(-1, 1) * follow["start_yaw_deg"])
    scale = 1.0 + float(rng.normal(0.0, float(noise["scale_error_std"])))
    color = bool(place["image"]["color"])
    threshold, lost, slow = float(place["localize"]["threshold"]), int(follow["lost_steps"]), float(follow["slow_mps"])
    gain = float(drive["expert"]["speed_gain"])
    obs = sim.reset(condition, seed, lateral, yaw)
    localization.start(rng)
    expected = sim.route.length_m / float(drive["expert"]["cruise_mps"]) * sim.spec.control_hz  # steps at cruise speed
    every = max(1, int(expected // strip_frames)) if strip_frames else 0
    xy, errors, frames, since_sure, slow_steps, lat = [sim.centre], [], [], 0, 0, []
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
        obs, status = sim.step(control)
        xy.append(sim.centre)
        lat.append(abs(sim.lateral))
        if obs is None:
            break
    seconds = time.perf_counter() - started
    return Episode(status, sim.t, sim.s, np.asarray(xy), np.asarray(errors), slow_steps, seconds,
                   float(np.mean(lat)) if lat else 0.0, frames)
