"""The controller at the wheel of the simulator: DAgger rounds (Ross, Gordon & Bagnell 2011) and the closed-loop
check of a trained controller on routes it never saw.

**DAgger.** A controller taught only from the expert's drives (widened by noise injection and side views) makes small
errors that take it to states the expert never visited, where its errors grow. Each round (``drive.dagger``):

* **Drive**: every training route of the demonstrations (:func:`topoloc.drive.demonstrations.training_route`, the
  validation routes excepted) under its training conditions, from ``drive.follow``'s start offsets, driven by the
  controller: Topo-DLM is given the route's command at the vehicle's progress, Topo-LP the lane's local-path image
  there (the path noise of ``drive.path_noise`` is added in training, as for the demonstrations). While the vehicle
  is, or at its speed and steering angle would be ``takeover_s`` later, more than ``takeover_m`` off the lane the
  expert drives, until both are back within a third of that: the drive goes on past the controller's mistakes (a car
  missing a bend at speed is off the road before its offset alone would call the expert) and the way back is recorded too.
* **Label**: every ``record_every``-th step, with the expert's steering, throttle and target speed at the state
  reached (recorded as ``perturbed``: off the expert's own path). Steps near the teach route are dropped, as in the
  demonstrations, and so are the last steps before a failure.
* **Train**: ``epochs`` more epochs from the controller's weights on the demonstrations and every round's steps;
  the best checkpoint on the validation routes (the demonstrations' only) is kept.

**Closed-loop check** (``drive.check``, :func:`closed_loop_check`): the controller alone drives ``routes`` random
routes drawn apart from the training routes (their own seed stream; away from the teach route too), one repeat
condition each in turn (``place.repeat_conditions``: the held-out condition included), told the route's command or
local path (no localization error). Its success rate over many routes and start points says more of the controller
than the one teach route of ``follow_route``, and costs a few seconds a route.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from topoloc.drive.demonstrations import (
    DROP_BEFORE_FAILURE,
    Demonstrations,
    as_input,
    from_rows,
    keep_away,
    local_path,
    route_conditions,
    step_row,
    training_route,
)
from topoloc.drive.drive_route import DriveRoute
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.local_path import path_input
from topoloc.drive.simulator import RUNNING, SUCCESS, Control, Simulator, step_vehicle
from topoloc.drive.topo_lp import path_form, path_frame, told_path
from topoloc.errors import InputError


@dataclass(frozen=True)
class DaggerSettings:
    """``drive.dagger`` in the config: rounds, training epochs per round, the expert's takeover offset (m) and look-ahead (s)."""

    rounds: int = 0
    epochs: int = 4
    takeover_m: float = 1.0
    takeover_s: float = 1.0

    @classmethod
    def from_conf(cls, dagger: dict[str, Any]) -> DaggerSettings:
        """Settings of a validated ``drive.dagger`` slice."""
        settings = cls(int(dagger["rounds"]), int(dagger["epochs"]), float(dagger["takeover_m"]), float(dagger["takeover_s"]))
        if settings.rounds < 0:
            raise InputError("drive.dagger.rounds", f"must be 0 or more, got {settings.rounds}")
        if settings.rounds and settings.epochs < 1:
            raise InputError("drive.dagger.epochs", f"must be at least 1, got {settings.epochs}")
        if settings.takeover_m <= 0:
            raise InputError("drive.dagger.takeover_m", f"must be positive, got {settings.takeover_m}")
        if settings.takeover_s < 0:
            raise InputError("drive.dagger.takeover_s", f"must be 0 or more, got {settings.takeover_s}")
        return settings


def controller_input(controller: Any, route: DriveRoute, s: float, centre: NDArray[np.float64], yaw: float) -> Any:
    """What ``controller`` is told at arc length ``s``, without error: a controller told a path (Topo-LP, Topo-DLM told
    the move) the local-path plane of the lane in its frame and form, the discrete Topo-DLM the command index."""
    if told_path(controller):
        return path_input(local_path(route, s, centre, yaw), path_frame(controller), form=path_form(controller))
    return int(route.command_at(s))


def offset_ahead(sim: Simulator, seconds: float) -> float:
    """The vehicle's offset from the lane (m, + right) ``seconds`` on if it kept its speed and steering angle."""
    state, spec = sim.state, sim.spec
    hold = Control(state.delta / np.radians(spec.max_steer_deg), 0.0)
    for _ in range(round(seconds * spec.control_hz)):
        state = step_vehicle(state, hold, spec)
    _, lateral, _ = sim.route.project(state.centre(spec), sim.s, 5.0, 5.0 + state.v * seconds * 2.0)
    return float(lateral)


def drive_on_policy(sim: Simulator, expert: Expert, controller: Any, condition: str, seed: int,
                    conf: dict[str, Any], conditions: list[str], route_index: int,
                    settings: DaggerSettings, record: bool = True) -> tuple[Demonstrations, str, float]:
    """One drive of ``sim``'s route by ``controller``, the expert taking over (see the module docstring): its steps
    labelled by the expert (none without ``record``), the outcome and the share of steps the expert drove."""
    drive = conf["drive"]
    every = int(drive["demonstrations"].get("record_every", 1))
    color = bool(conf["place"]["image"]["color"])
    follow = drive["follow"]
    rng = np.random.default_rng([seed, 59])
    obs = sim.reset(condition, seed, float(rng.uniform(-1, 1) * follow["start_lateral_m"]),
                    float(rng.uniform(-1, 1) * follow["start_yaw_deg"]))
    expert.reset()
    rows: list[tuple[Any, ...]] = []
    status, expert_drives, expert_steps = RUNNING, False, 0
    while status == RUNNING:
        label = expert.control(sim.state)
        image, centre, yaw = as_input(obs.image, color), sim.centre, sim.state.yaw
        if record and sim.t % every == 0:
            rows.append(step_row(sim.route, obs.image, obs.speed, sim.s, label, expert.last_target, True, centre, yaw,
                                 sim.lateral, color))
        limit = settings.takeover_m / 3.0 if expert_drives else settings.takeover_m
        expert_drives = max(abs(sim.lateral), abs(offset_ahead(sim, settings.takeover_s))) > limit
        if expert_drives:
            control, expert_steps = label, expert_steps + 1
        else:
            control = Control(*controller.act(image, obs.speed, controller_input(controller, sim.route, sim.s, centre, yaw)))
        obs, status = sim.step(control)
    if status != SUCCESS:
        rows = rows[: max(0, len(rows) - DROP_BEFORE_FAILURE // every)]
    return from_rows(rows, sim, color, conditions, condition, route_index), status, expert_steps / max(sim.t, 1)


def collect(controller: Any, conf: dict[str, Any], round_index: int, avoid_xy: NDArray[np.float64] | None,
            make_route: Any, make_simulator: Any) -> tuple[Demonstrations, dict[str, float]]:
    """One round's on-policy steps on every training route of the demonstrations (``conf``: ``drive``, ``place``,
    ``render``; ``make_route`` / ``make_simulator`` as for :func:`topoloc.drive.demonstrations.demonstrate`)."""
    drive = conf["drive"]
    demo_conf = drive["demonstrations"]
    conditions = [str(c) for c in demo_conf["conditions"]]
    settings = DaggerSettings.from_conf(drive["dagger"])
    expert_settings = ExpertSettings.from_conf(drive["expert"])
    routes = int(demo_conf["routes"]) - int(demo_conf["val_routes"])
    parts, outcomes, taken = [], [], []
    for r in tqdm(range(routes), desc=f"DAgger round {round_index + 1}", unit="route"):
        route = training_route(r, conf, avoid_xy, make_route, candidates=int(demo_conf["candidates"]),
                               wide_middle_share=float(demo_conf.get("wide_middle_share", 0.0)),
                               sharp_turn_share=float(demo_conf.get("sharp_turn_share", 0.0)))
        sim = make_simulator(route)
        expert = Expert(route, sim.spec, expert_settings)
        for c in route_conditions(r, len(conditions), demo_conf.get("conditions_per_route")):
            seed = int(np.random.SeedSequence([int(drive["seed"]), 47, round_index, r, c]).generate_state(1)[0])
            demo, status, share = drive_on_policy(sim, expert, controller, conditions[c], seed, conf, conditions, r, settings)
            outcomes.append(status)
            taken.append(share)
            parts.append(keep_away(demo, avoid_xy, float(demo_conf["min_distance_m"])))
    steps = Demonstrations.concat(parts)
    facts = {"steps": float(len(steps)), "drives": float(len(outcomes)),
             "finished_share": float(np.mean([o == SUCCESS for o in outcomes])),
             "expert_share": float(np.mean(taken)),
             "mean_abs_lateral_m": float(np.abs(steps.lateral).mean()) if len(steps) else 0.0}
    return steps, facts


#: Seed stream of the closed-loop check's routes (the training routes draw from stream 41).
CHECK_STREAM = 67


def check_route(r: int, controller: Any, conf: dict[str, Any], avoid_xy: NDArray[np.float64] | None,
                make_route: Any, make_simulator: Any) -> tuple[str, str, float]:
    """Check route ``r`` of :func:`closed_loop_check`, driven by the controller alone: its condition, the drive's
    outcome and the share of the route driven. Depends on ``r`` and the config alone, so routes can be checked in
    any order or in parallel."""
    drive = conf["drive"]
    conditions = [str(c) for c in conf["place"]["repeat_conditions"]]
    route = training_route(r, conf, avoid_xy, make_route, stream=CHECK_STREAM)
    sim = make_simulator(route)
    condition = conditions[r % len(conditions)]
    seed = int(np.random.SeedSequence([int(drive["seed"]), CHECK_STREAM, r]).generate_state(1)[0])
    alone = DaggerSettings(rounds=0, epochs=1, takeover_m=float("inf"), takeover_s=0.0)
    _, status, _ = drive_on_policy(sim, Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"])), controller,
                                   condition, seed, conf, conditions, r, alone, record=False)
    return condition, status, min(1.0, sim.s / max(route.length_m - sim.spec.goal_m, 1e-9))


def check_metrics(rows: list[tuple[str, str, float]]) -> dict[str, float]:
    """The metrics ``check/...`` of the rows of :func:`check_route`: ``routes``, ``success_rate``, ``share_driven``
    (mean share of each route driven), ``success_<condition>`` and the count of each failure outcome."""
    out = {"check/routes": float(len(rows)), "check/success_rate": float(np.mean([s == SUCCESS for _, s, _ in rows])),
           "check/share_driven": float(np.mean([share for _, _, share in rows]))}
    for c in dict.fromkeys(c for c, _, _ in rows):
        out[f"check/success_{c}"] = float(np.mean([s == SUCCESS for cc, s, _ in rows if cc == c]))
    for outcome in sorted({s for _, s, _ in rows} - {SUCCESS}):
        out[f"check/{outcome}"] = float(sum(s == outcome for _, s, _ in rows))
    return out


def closed_loop_check(controller: Any, conf: dict[str, Any], avoid_xy: NDArray[np.float64] | None,
                      make_route: Any, make_simulator: Any) -> dict[str, float]:
    """The controller's success on ``drive.check.routes`` routes it never trained on (see the module docstring;
    :func:`check_route`, :func:`check_metrics`)."""
    routes = int(conf["drive"]["check"]["routes"])
    return check_metrics([check_route(r, controller, conf, avoid_xy, make_route, make_simulator)
                          for r in tqdm(range(routes), desc="closed-loop check", unit="route")])
