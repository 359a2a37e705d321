"""Stage ``follow_route``: teach and repeat in closed loop, per condition, agent and localization (Cai & Wan, Tables 1-2).

The evaluation routes lie on the teach route of the topometric map (``place.route``): ``drive.follow.routes`` routes
of ``drive.follow.length_m`` starting evenly from its start to that length before its end (one route: the first
``length_m``), each driven with the map of its own stretch of the teach drive, as if taught alone
(:func:`topoloc.drive.repeat_routes.repeat_routes`). On every route, for every repeat condition
(``place.repeat_conditions``) and each of ``drive.follow.repeats`` seeds, every agent of ``drive.follow.agents``
(``dlm``: Topo-DLM; ``lp``: Topo-LP; ``replay``: the teach drive's steering per vertex, recorded from the expert's
teach drive of that route) drives it with every localization of ``drive.follow.localization`` (``ground_truth`` or a
place localizer of the registry, with the retrieval network's scores; :mod:`topoloc.drive.localization_adapters`), under the
teach drive's speed ahead on the map (``drive.follow.teach_speed_ahead_m``). The same seed gives every agent the same
start offset and odometry noise.

Outputs: ``episodes`` (one row per drive: outcome, progress, localization error, speed of the loop),
``summary`` (success rate per condition and agent, over routes and repeats), ``table`` (like the paper's Tables 1
and 2: success rate per condition and the mean, held-out conditions of the controller's training marked; with several
routes also per route), ``metrics`` (success per agent and route; ``intersections`` and ``shared_m`` summed over the
routes, a stretch counted once per route that holds it), ``paths``
(the driven paths over the map), ``success`` (bars) and ``strip`` (frames of one repeat per condition).

The **junction benchmark** (:mod:`topoloc.drive.junctions`): every junction of every route, for every drive of every
agent and localization and for the expert's own drives (``expert (ground truth)``: the same starts, under each
condition), taken as commanded or not, with its turn class, kind, distance from the previous junction and the speed
on entry: ``junctions`` (one row per drive and junction), ``junction_figure`` (share taken per turn class and kind) and
a section of ``table``. ``movie_<agent>`` (optional): one repeat drive per agent to watch (:mod:`topoloc.drive.movie`).
``traces`` (optional): every drive's vehicle, speed, localization and command over time, ``drive.follow.trace_hz``
rows a second (:mod:`topoloc.drive.traces`; the teach-and-repeat viewer replays them).
"""

from __future__ import annotations

import logging
from functools import partial
from typing import Any, cast

import numpy as np
import pandas as pd
import torch
from tqdm import tqdm

from topoloc.drive.agents import (
    ExpertAgent,
    ReplayAgent,
    TeachImages,
    controller_agent,
    method_name,
)
from topoloc.drive.camera import image_shape, place_window
from topoloc.drive.episodes import run_episode, speed_limit_ahead, teach_controls
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.follow_report import write_follow_report
from topoloc.drive.junctions import junction_results, roundabout_ways, route_junctions
from topoloc.drive.localization_adapters import GroundTruth, PlaceLocalization
from topoloc.drive.movie import write_movie
from topoloc.drive.repeat_routes import intersections, repeat_routes
from topoloc.drive.routes import make_simulator, teach_route
from topoloc.drive.topo_lp import CONTROLLERS, load_controller
from topoloc.drive.traces import episode_trace, write_traces
from topoloc.graph.road_graph import RoadGraph
from topoloc.localizer import PLACE_OBSERVATIONS
from topoloc.place.network import load_model
from topoloc.place.topometric_localization import PlaceLocalizer
from topoloc.place.topometric_map import TopometricMap
from topoloc.registry import check_names, make
from topoloc.render.conditions import check_conditions

log = logging.getLogger(__name__)


def place_localization(name: str, topo: TopometricMap, model: Any, conf: dict[str, Any]) -> PlaceLocalization:
    """A new localization by the registered place localizer ``name`` on ``topo``, scored by the retrieval ``model``
    (``conf``: the ``drive``, ``place`` and ``render`` slices: ``place.localize`` and the place images' window)."""
    return PlaceLocalization(cast(PlaceLocalizer, make(name, PLACE_OBSERVATIONS)), topo, model, conf["place"]["localize"],
                             place_window(conf))


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Drive every repeat; write the episode table, summary, tables, metrics and figures."""
    drive, place = conf["drive"], conf["place"]
    follow = drive["follow"]
    torch.set_num_threads(int(drive["threads"]))
    names = check_conditions({"teach_condition": place["teach_condition"], "repeat_conditions": place["repeat_conditions"]})
    trained = [str(c) for c in drive["demonstrations"]["conditions"]]
    held_out = [c for c in names["repeat"] if c not in trained]
    localizations = [str(n) for n in follow["localization"]]
    place_names = [n for n in localizations if n != "ground_truth"]
    check_names(place_names, "drive.follow.localization", PLACE_OBSERVATIONS)
    graph = RoadGraph.load(inputs["graph"])
    parts = repeat_routes(teach_route(graph, conf), TopometricMap.load(inputs["map"]), follow["length_m"],
                          int(follow["routes"]))
    controllers = {a: load_controller(inputs[f"controller_{a}"], image_shape(conf), "drive.camera")
                   for a in follow["agents"] if a in CONTROLLERS}
    retrieval = load_model(inputs["model"]) if place_names else None
    ahead = follow["teach_speed_ahead_m"]
    rows, traces, strips, junction_rows, movies, steps = [], {}, [], [], {}, []
    strip_method = (next((a for a in ("lp", "dlm") if a in follow["agents"]), follow["agents"][0]),
                    place_names[0] if place_names else "ground_truth")
    movie_loc, movie_every = place_names[0] if place_names else "ground_truth", int(follow["movie"]["every_steps"])
    jconf = follow["junctions"]
    roundabouts = roundabout_ways(inputs.get("osm"))
    runs = [(c, r, a, loc) for c in names["repeat"] for r in range(int(follow["repeats"]))
            for a in follow["agents"] for loc in localizations]
    expert_runs = [(c, r, "expert", "ground_truth") for c in names["repeat"] for r in range(int(follow["repeats"]))]
    progress = tqdm(total=len(parts) * (len(runs) + len(expert_runs)), desc="repeat drives", unit="drive")
    for k, part in enumerate(parts):
        route, topo, lane_s = part.route, part.topo, part.lane_s
        sim = make_simulator(inputs.get("osm"), graph, route, conf)
        expert = Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
        teach_steer, teach_speed = teach_controls(sim, expert, place["teach_condition"], int(drive["seed"]), lane_s)
        limit = None if ahead is None else speed_limit_ahead(teach_speed, lane_s, float(ahead))
        teach = TeachImages(sim, topo, place["teach_condition"], int(drive["seed"]), bool(place["image"]["color"]))
        agents = {"dlm": partial(controller_agent, controllers.get("dlm"), topo, teach),
                  "lp": partial(controller_agent, controllers.get("lp"), topo, teach),
                  "replay": partial(ReplayAgent, teach_steer, teach_speed, float(drive["expert"]["speed_gain"])),
                  "expert": partial(ExpertAgent, expert, sim)}
        junctions = route_junctions(graph, route, roundabouts, float(jconf["cluster_m"]), float(jconf["around_m"]))
        locs = {"ground_truth": partial(GroundTruth, lane_s)}
        for name in place_names:
            locs[name] = partial(place_localization, name, topo, retrieval, conf)
        for condition, repeat, agent, loc in runs + expert_runs:
            seed = int(np.random.SeedSequence([int(drive["seed"]), 59, names["repeat"].index(condition), repeat, k])
                       .generate_state(1)[0])
            want_strip = k == 0 and repeat == 0 and (agent, loc) == strip_method
            want_movie = (k == 0 and repeat == 0 and condition == names["repeat"][0] and loc == movie_loc
                          and f"movie_{agent}" in outputs)
            episode = run_episode(sim, agents[agent](), locs[loc](), topo, condition, seed, conf,
                                  int(follow["strip_frames"]) if want_strip else 0, None if agent == "expert" else limit,
                                  movie_every if want_movie else 0)
            key = f"{k}/{condition}/{repeat}/{agent}/{loc}"
            method = "expert (ground truth)" if agent == "expert" else method_name(agent, loc)
            junction_rows += [{"episode": key, "route": k, "condition": condition, "repeat": repeat, "agent": method, **j}
                              for j in junction_results(junctions, episode.s, episode.speed, episode.outcome,
                                                        float(jconf["before_m"]), float(jconf["after_m"]))]
            if want_movie and agent != "expert":
                movies[agent] = (f"{method}, {condition}: {episode.outcome}", episode.movie, route.xy, topo.gt_xy)
            if agent == "expert":
                progress.update()
                continue
            traces[key] = episode.xy
            if "traces" in outputs:
                steps.append(episode_trace(episode, topo, sim.spec.control_hz, float(follow["trace_hz"]), episode=key,
                                           route=k, condition=condition, repeat=repeat, agent=method, localization=loc))
            if want_strip:
                strips.append((f"{condition}: {episode.outcome}", episode.frames))
            rows.append({"episode": key, "route": k, "route_start_m": part.start_m, "route_length_m": route.length_m,
                         "route_shared_m": route.shared_m,
                         "intersections": intersections(topo.command[lane_s < route.length_m]),
                         "condition": condition, "repeat": repeat, "agent": method_name(agent, loc),
                         "outcome": episode.outcome, "success": episode.outcome == "success", "steps": episode.steps,
                         "progress_m": episode.progress_m, "progress_share": episode.progress_m / route.length_m,
                         "mean_loc_error_m": float(np.mean(episode.loc_error_m)) if len(episode.loc_error_m) else 0.0,
                         "slow_steps": episode.slow_steps, "mean_abs_lateral_m": episode.mean_abs_lateral_m,
                         "steps_per_s": episode.steps / max(episode.seconds, 1e-9)})
            log.info("%s: %s after %.0f m", key, episode.outcome, episode.progress_m)
            progress.update()
    progress.close()
    episodes = pd.DataFrame(rows)
    if "traces" in outputs:
        size = write_traces(steps, outputs["traces"])
        log.info("traces: %d rows of %d drives, %.0f kB", sum(len(s) for s in steps), len(steps), size / 1e3)
    movie = follow["movie"]
    for agent, (title, frames, lane, vertex_xy) in movies.items():
        size = write_movie(frames, lane, vertex_xy, title, outputs[f"movie_{agent}"], int(movie["height_px"]),
                           int(movie["fps"]))
        log.info("movie of %s: %d frames, %.1f MB", agent, len(frames), size / 1e6)
    return write_follow_report(episodes, traces, strips, parts, graph, conf, held_out, outputs,
                               f"{method_name(*strip_method)}: one repeat drive per condition", pd.DataFrame(junction_rows))
