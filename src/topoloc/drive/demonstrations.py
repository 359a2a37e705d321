"""The expert's demonstrations: images, speed, command, local path and controls on the training routes.

Per training route and training condition (``drive.demonstrations``) the expert
(:mod:`topoloc.drive.expert`) drives the route in the simulator with noise injection; every
``record_every``-th step is kept with its camera image (the place images' camera), speed, command, the
expert's steering, throttle and target speed (the labels), whether the step was perturbed, the pose and the lateral
offset, and the **local path** (the lane's next ``LOCAL_PATH_M`` metres in the vehicle frame, every metre:
what Topo-LP is given, in its lane's frame). With ``side_views`` each kept step adds views from poses beside the
vehicle's, labelled with the expert's control from there (:func:`side_view`). Routes take ``conditions_per_route``
of the conditions (:func:`route_conditions`). Steps closer than ``min_distance_m`` to the teach route are dropped,
so training and evaluation places are disjoint; a route keeping fewer than ``min_steps`` steps is drawn
again. The last ``val_routes`` routes are for validation. A route's drives depend on its index and the config alone
(:func:`demonstrate_route`), so routes can be recorded in any order, or in separate processes, with the same result.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from topoloc.drive.drive_route import DriveRoute
from topoloc.drive.expert import Expert, ExpertSettings, NoiseInjector, NoiseSettings
from topoloc.drive.lane_geometry import DENSE_M, lane_curvature
from topoloc.drive.simulator import RUNNING, SUCCESS, Control, Simulator, VehicleState
from topoloc.drive.turn_routes import SHARP_TURN_DEG
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.place.images import polyline_distance
from topoloc.render.conditions import get_condition

log = logging.getLogger(__name__)

LOCAL_PATH_M = 20
#: Steps before a failure that are not kept (the expert was already losing the road).
DROP_BEFORE_FAILURE = 20
#: A bend of the lane tighter than this radius (metres) is sharp (``drive.demonstrations.candidates``).
SHARP_RADIUS_M = 15.0
#: A route drawn for ``drive.demonstrations.wide_middle_share`` keeps at least this share of its lane in the middle of a
#: wide unmarked carriageway, and is drawn up to this many times per candidate.
WIDE_MIDDLE_MIN = 0.5
WIDE_MIDDLE_ATTEMPTS = 60


def as_input(image: NDArray[np.uint8], color: bool) -> NDArray[np.uint8]:
    """The camera image as the networks take it: BGR (H, W, 3), or grey (H, W, 1)."""
    return image if color else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)[..., None]


def local_path(route: DriveRoute, s: float, xy: NDArray[np.float64], yaw: float) -> NDArray[np.float32]:
    """The lane's next :data:`LOCAL_PATH_M` metres from arc length ``s``, every metre, in the vehicle frame (x ahead, y left);
    near the route's end the lane goes on straight (:meth:`DriveRoute.point_ahead`), as the expert aims."""
    pts = np.stack([route.point_ahead(s + d) for d in range(1, LOCAL_PATH_M + 1)]) - xy
    c, sn = np.cos(yaw), np.sin(yaw)
    return np.column_stack([pts[:, 0] * c + pts[:, 1] * sn, -pts[:, 0] * sn + pts[:, 1] * c]).astype(np.float32)


@dataclass
class Demonstrations:
    """Recorded steps: ``images`` (n, H, W, C) uint8 and per step its route, condition index, speed, command,
    labels ``steer`` / ``throttle`` / ``target_speed``, ``perturbed``, pose ``xy`` / ``yaw``, ``lateral`` offset and ``path`` (n, 20, 2)."""

    images: NDArray[np.uint8]
    conditions: list[str]
    route: NDArray[np.int64]
    condition: NDArray[np.int64]
    speed: NDArray[np.float32]
    command: NDArray[np.int64]
    steer: NDArray[np.float32]
    throttle: NDArray[np.float32]
    target_speed: NDArray[np.float32]
    perturbed: NDArray[np.bool_]
    xy: NDArray[np.float64]
    yaw: NDArray[np.float64]
    lateral: NDArray[np.float32]
    path: NDArray[np.float32]

    FIELDS = ("route", "condition", "speed", "command", "steer", "throttle", "target_speed", "perturbed", "xy", "yaw", "lateral", "path")

    def __len__(self) -> int:
        return len(self.images)

    def save(self, path: str | Path) -> None:
        """Write as ``.npz``, atomically."""
        with atomic_path(path) as tmp, open(tmp, "wb") as handle:
            np.savez(handle, images=self.images, conditions=np.array(self.conditions),
                     **{k: getattr(self, k) for k in self.FIELDS})

    @classmethod
    def load(cls, path: str | Path) -> Demonstrations:
        """Read a file written by :meth:`save`; InputError naming the file otherwise."""
        try:
            with np.load(path) as data:
                return cls(data["images"], [str(c) for c in data["conditions"]], **{k: data[k] for k in cls.FIELDS})
        except (OSError, KeyError, ValueError) as err:
            raise InputError(path, f"not a demonstrations file ({err})") from err

    @classmethod
    def concat(cls, parts: list[Demonstrations]) -> Demonstrations:
        """Steps of several recordings with the same conditions, one after the other."""
        return cls(np.concatenate([p.images for p in parts]), list(parts[0].conditions),
                   **{k: np.concatenate([getattr(p, k) for p in parts]) for k in cls.FIELDS})

    @classmethod
    def pool(cls, maps: list[Demonstrations]) -> Demonstrations:
        """The demonstrations of several maps as one set: route ``k`` of map ``i`` becomes route ``k * len(maps) + i``
        (a map of fewer routes has its ``k`` shifted up to end with the others: its last route is the last of all too),
        so the last routes (the validation routes, :class:`~topoloc.drive.controller_training.DemoData`) come from
        every map in turn. ValueError when the maps' images or conditions differ."""
        first = maps[0]
        for other in maps[1:]:
            if other.images.shape[1:] != first.images.shape[1:]:
                raise ValueError(f"images of {other.images.shape[1:]} against {first.images.shape[1:]}")
            if other.conditions != first.conditions:
                raise ValueError(f"conditions {other.conditions} against {first.conditions}")
        last = [int(demos.route.max()) if len(demos) else 0 for demos in maps]
        renumbered = [replace(demos, route=(demos.route + max(last) - last[i]) * len(maps) + i)
                      for i, demos in enumerate(maps)]
        return cls.concat(renumbered)


@dataclass(frozen=True)
class SideViews:
    """``drive.demonstrations.side_views``: extra views per kept step from poses beside the vehicle's."""

    count: int = 0
    lateral_m: float = 1.5
    yaw_deg: float = 10.0


def side_view(sim: Simulator, expert: Expert, rng: np.random.Generator, side: SideViews, color: bool) -> tuple[Any, ...]:
    """One view from a pose up to ``side.lateral_m`` beside and ``side.yaw_deg`` off the vehicle's, with the expert's
    control from there as the label (the recovery a side camera teaches; the drive itself is not changed)."""
    state, spec = sim.state, sim.spec
    lateral, dyaw = rng.uniform(-1, 1) * side.lateral_m, np.radians(rng.uniform(-1, 1) * side.yaw_deg)
    yaw = state.yaw + dyaw
    centre = sim.centre + lateral * np.array([np.sin(state.yaw), -np.cos(state.yaw)])
    h = 0.5 * spec.wheelbase_m
    virtual = VehicleState(centre[0] - h * np.cos(yaw), centre[1] - h * np.sin(yaw), yaw, state.v, state.delta)
    saved = expert.s_rear, expert.last_target
    label = expert.control(virtual)
    row_target = expert.last_target
    expert.s_rear, expert.last_target = saved
    s, off, _ = sim.route.project(centre, sim.s)
    image = sim._render.render(centre, yaw, sim.t)
    return step_row(sim.route, image, state.v, s, label, row_target, True, centre, yaw, off, color)


def step_row(route: DriveRoute, image: NDArray[np.uint8], speed: float, s: float, label: Control, target_speed: float,
             perturbed: bool, centre: NDArray[np.float64], yaw: float, lateral: float, color: bool) -> tuple[Any, ...]:
    """One recorded step in the field order of :class:`Demonstrations` (image first); ``label`` is the expert's control."""
    return (as_input(image, color), speed, route.command_at(s), label.steer, label.throttle, target_speed, perturbed,
            centre, yaw, lateral, local_path(route, s, centre, yaw))


def from_rows(rows: list[tuple[Any, ...]], sim: Simulator, color: bool, conditions: list[str], condition: str,
              route_index: int) -> Demonstrations:
    """The :class:`Demonstrations` of rows of :func:`step_row` recorded on ``sim``'s route under ``condition``."""
    n = len(rows)
    cols = list(zip(*rows)) if rows else [[] for _ in range(11)]
    shape = (0, sim.rig.height, sim.rig.width, 3 if color else 1)
    return Demonstrations(np.stack(cols[0]) if n else np.zeros(shape, np.uint8), list(conditions),
                          np.full(n, route_index, np.int64), np.full(n, conditions.index(condition), np.int64),
                          np.asarray(cols[1], np.float32), np.asarray(cols[2], np.int64), np.asarray(cols[3], np.float32),
                          np.asarray(cols[4], np.float32), np.asarray(cols[5], np.float32), np.asarray(cols[6], bool),
                          np.asarray(cols[7], float).reshape(n, 2), np.asarray(cols[8], float), np.asarray(cols[9], np.float32),
                          np.asarray(cols[10], np.float32).reshape(n, LOCAL_PATH_M, 2))


def record(sim: Simulator, expert: Expert, condition: str, seed: int, noise: NoiseSettings, every: int, color: bool,
           conditions: list[str], route_index: int, side: SideViews = SideViews()) -> tuple[Demonstrations, str]:
    """One noisy expert drive of ``sim``'s route under ``condition``: its kept steps (and side views) and the outcome."""
    rng = np.random.default_rng([seed, 31])
    side_rng = np.random.default_rng([seed, 37])
    injector = NoiseInjector(noise, sim.spec.control_hz, rng)
    obs = sim.reset(condition, seed)
    expert.reset()
    rows: list[tuple[Any, ...]] = []
    status = RUNNING
    while status == RUNNING:
        label = expert.control(sim.state)
        offset = injector.offset()
        if sim.t % every == 0:
            rows.append(step_row(sim.route, obs.image, obs.speed, sim.s, label, expert.last_target, offset != 0.0,
                                 sim.centre, sim.state.yaw, sim.lateral, color))
            rows += [side_view(sim, expert, side_rng, side, color) for _ in range(side.count)]
        obs, status = sim.step(Control(float(np.clip(label.steer + offset, -1, 1)), label.throttle))
    if status != SUCCESS:
        rows = rows[: max(0, len(rows) - (1 + side.count) * (DROP_BEFORE_FAILURE // every))]
    return from_rows(rows, sim, color, conditions, condition, route_index), status


def keep_away(demo: Demonstrations, avoid_xy: NDArray[np.float64] | None, min_distance_m: float) -> Demonstrations:
    """The steps at least ``min_distance_m`` from the polyline ``avoid_xy``."""
    if avoid_xy is None or not len(demo):
        return demo
    keep = polyline_distance(demo.xy, avoid_xy) >= min_distance_m
    return Demonstrations(demo.images[keep], demo.conditions, **{k: getattr(demo, k)[keep] for k in Demonstrations.FIELDS})


def route_conditions(route: int, n: int, per_route: int | None) -> list[int]:
    """Indices of the conditions route ``route`` is driven under: ``per_route`` of the ``n``, cyclically from ``route``."""
    if per_route is None or per_route >= n:
        return list(range(n))
    return [(route + k) % n for k in range(int(per_route))]


def sharp_m(route: DriveRoute) -> float:
    """Metres of the route's lane in bends tighter than :data:`SHARP_RADIUS_M`."""
    return float((lane_curvature(route.xy) > 1.0 / SHARP_RADIUS_M).sum()) * DENSE_M


def wide_middle_route(r: int, share: float) -> bool:
    """Whether training route ``r`` is one of the ``share`` of the routes, spread evenly over the indices, that must
    run mostly in the middle of a wide unmarked carriageway (``drive.demonstrations.wide_middle_share``)."""
    return int(np.floor((r + 1) * share)) > int(np.floor(r * share))


def sharp_turn_route(r: int, share: float) -> bool:
    """Whether training route ``r`` is one of the ``share`` of the routes, spread evenly over the indices (half a
    period after :func:`wide_middle_route`'s), drawn through one of the map's sharp turns
    (``drive.demonstrations.sharp_turn_share``, :mod:`topoloc.drive.turn_routes`)."""
    return int(np.floor((r + 1) * share + 0.5)) > int(np.floor(r * share + 0.5))


def training_route(r: int, conf: dict[str, Any], avoid_xy: NDArray[np.float64] | None, make_route: Any,
                   stream: int = 41, candidates: int = 1, wide_middle_share: float = 0.0,
                   sharp_turn_share: float = 0.0) -> DriveRoute:
    """Training route ``r``: of its seeded draws ``make_route(rng)`` that keep ``min_steps`` recorded steps
    ``min_distance_m`` away from ``avoid_xy``, the first ``candidates`` ones, and of those the one with the most lane
    in sharp bends (:func:`sharp_m`; the same route on every call: DAgger drives the demonstrations' routes; another
    ``stream`` draws other routes the same way). When :func:`sharp_turn_route` picks ``r`` for ``sharp_turn_share``,
    the draws are ``make_route.through_turn(rng)`` (:class:`topoloc.drive.turn_routes.TrainingRoutes`; on a map
    without sharp turns the others, with a warning), and the first kept is the route; else when :func:`wide_middle_route` picks ``r`` for
    ``wide_middle_share``, only draws with at least :data:`WIDE_MIDDLE_MIN` of their lane in the middle of a wide
    unmarked carriageway count (:attr:`DriveRoute.wide_middle_share`; if no draw has that, the others, with a warning).
    InputError naming ``drive.lane.max_shared_m`` when no draw gave a route, ``drive.demonstrations.min_distance_m``
    when none kept away from ``avoid_xy``."""
    drive = conf["drive"]
    demo_conf = drive["demonstrations"]
    every = int(demo_conf.get("record_every", 1))
    step_m = float(drive["expert"]["cruise_mps"]) / float(drive["episode"]["control_hz"])
    draw = make_route
    if sharp_turn_route(r, float(sharp_turn_share)):
        if getattr(make_route, "turns", None):
            draw = make_route.through_turn
        else:
            log.warning("training route %d: the map has no turn of %.0f deg or more for "
                        "drive.demonstrations.sharp_turn_share; drawn as the others", r, SHARP_TURN_DEG)
    wide = draw is make_route and wide_middle_route(r, float(wide_middle_share))
    if draw is not make_route:
        candidates = 1  # drawn through a chosen turn already: ranked by their bends, small loops would win
    drawn, kept, other = 0, [], []
    attempts = (WIDE_MIDDLE_ATTEMPTS if wide or draw is not make_route else 20) * int(candidates)
    for attempt in range(attempts):
        route = draw(np.random.default_rng([int(drive["seed"]), stream, r, attempt]))
        if route is None:
            continue
        drawn += 1
        near = polyline_distance(route.xy[::8], avoid_xy) < float(demo_conf["min_distance_m"]) if avoid_xy is not None \
            else np.zeros(len(route.xy[::8]), bool)
        if (1.0 - near.mean()) * route.length_m / step_m / every >= int(demo_conf["min_steps"]):
            if wide and route.wide_middle_share < WIDE_MIDDLE_MIN:
                if len(other) < candidates:  # the fallback keeps the first ones only
                    other.append(route)
                continue
            kept.append(route)
            if len(kept) >= candidates:
                break
    if not kept and other:
        log.warning("training route %d: no draw runs %.0f%% in the middle of a wide unmarked road "
                    "(drive.demonstrations.wide_middle_share); drawn as the others", r, 100 * WIDE_MIDDLE_MIN)
        kept = other[:candidates]
    if kept:
        return max(kept, key=sharp_m)  # the first of equals: one candidate gives the first route kept
    if not drawn:
        raise InputError("drive.lane.max_shared_m", f"route {r} (seed stream {stream}): none of {attempts} draws gave "
                         "a drivable route (each shared more lane with another road's carriageway, ran into a dead "
                         "end before half of drive.demonstrations.route_length_m, or could not be built)")
    raise InputError("drive.demonstrations.min_distance_m", f"route {r} (seed stream {stream}): no route keeps "
                     f"{demo_conf['min_steps']} steps {demo_conf['min_distance_m']} m away from the teach route")


def demonstrate_route(r: int, conf: dict[str, Any], avoid_xy: NDArray[np.float64] | None, make_route: Any,
                      make_simulator: Any) -> tuple[list[Demonstrations], list[str], list[NDArray[np.bool_]]]:
    """Training route ``r`` (:func:`training_route`) under each of its conditions (:func:`route_conditions`): the kept
    steps of each drive, its outcome and whether each of its own steps was under noise injection. A route's drives
    depend on ``r`` and the config alone, so routes can be recorded in any order or in parallel."""
    drive = conf["drive"]
    demo_conf = drive["demonstrations"]
    conditions = [str(c) for c in demo_conf["conditions"]]
    every = int(demo_conf.get("record_every", 1))
    noise = NoiseSettings.from_conf(drive["noise"])
    color = bool(conf["place"]["image"]["color"])
    side = SideViews(int(demo_conf["side_views"]), float(demo_conf["side_lateral_m"]), float(demo_conf["side_yaw_deg"]))
    chosen = training_route(r, conf, avoid_xy, make_route, candidates=int(demo_conf["candidates"]),
                            wide_middle_share=float(demo_conf.get("wide_middle_share", 0.0)),
                            sharp_turn_share=float(demo_conf.get("sharp_turn_share", 0.0)))
    sim = make_simulator(chosen)
    expert = Expert(chosen, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    parts, outcomes, injected = [], [], []
    for c in route_conditions(r, len(conditions), demo_conf.get("conditions_per_route")):
        seed = int(np.random.SeedSequence([int(drive["seed"]), 43, r, c]).generate_state(1)[0])
        demo, status = record(sim, expert, conditions[c], seed, noise, every, color, conditions, r, side)
        outcomes.append(status)
        injected.append(demo.perturbed[:: 1 + side.count])  # the drive's own steps (side views follow each)
        parts.append(keep_away(demo, avoid_xy, float(demo_conf["min_distance_m"])))
    return parts, outcomes, injected


def demonstrate(osm: str | None, graph: RoadGraph, conf: dict[str, Any], avoid_xy: NDArray[np.float64] | None,
                make_route: Any, make_simulator: Any) -> tuple[Demonstrations, dict[str, float]]:
    """Record every training route under every training condition (``conf`` holds ``drive``, ``place``, ``render``).

    ``make_route(rng)`` draws a route (or None), ``make_simulator(route)`` builds its simulator.
    """
    demo_conf = conf["drive"]["demonstrations"]
    for i, name in enumerate(demo_conf["conditions"]):
        get_condition(str(name), f"drive.demonstrations.conditions.{i}")
    if int(demo_conf["val_routes"]) >= int(demo_conf["routes"]):
        raise InputError("drive.demonstrations.val_routes", "must be fewer than drive.demonstrations.routes")
    parts, outcomes, injected = [], [], []
    for r in tqdm(range(int(demo_conf["routes"])), desc="demonstration routes", unit="route"):
        route_parts, route_outcomes, route_injected = demonstrate_route(r, conf, avoid_xy, make_route, make_simulator)
        parts += route_parts
        outcomes += route_outcomes
        injected += route_injected
    return collect_demonstrations(parts, outcomes, injected, conf, avoid_xy)


def collect_demonstrations(parts: list[Demonstrations], outcomes: list[str], injected: list[NDArray[np.bool_]],
                           conf: dict[str, Any], avoid_xy: NDArray[np.float64] | None) -> tuple[Demonstrations, dict[str, float]]:
    """The routes' drives (:func:`demonstrate_route`, in route order) as one set, and its facts."""
    demo_conf = conf["drive"]["demonstrations"]
    demos = Demonstrations.concat(parts)
    if not len(demos):
        raise InputError("drive.demonstrations", "no demonstration step was kept")
    facts = {"steps": float(len(demos)), "routes": float(demo_conf["routes"]), "expert_episodes": float(len(outcomes)),
             "expert_success_rate": float(np.mean([o == SUCCESS for o in outcomes])),
             "perturbed_share": float(demos.perturbed.mean()),
             "noise_injected_share": float(np.concatenate(injected).mean()) if injected else 0.0,
             "mean_speed_mps": float(demos.speed.mean()),
             "mean_abs_lateral_m": float(np.abs(demos.lateral).mean()),
             "wide_middle_routes": float(sum(wide_middle_route(r, float(demo_conf.get("wide_middle_share", 0.0)))
                                             for r in range(int(demo_conf["routes"])))),
             "sharp_turn_routes": float(sum(sharp_turn_route(r, float(demo_conf.get("sharp_turn_share", 0.0)))
                                            for r in range(int(demo_conf["routes"]))))}
    facts |= {f"steps_{name}": float(np.sum(demos.command == i)) for i, name in
              enumerate(("follow", "left", "right", "straight"))}
    if avoid_xy is not None:
        facts["min_distance_to_teach_route_m"] = float(polyline_distance(demos.xy, avoid_xy).min())
    return demos, facts
