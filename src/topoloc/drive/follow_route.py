"""Stage ``follow_route``: teach and repeat in closed loop, per condition, agent and localization (Cai & Wan, Tables 1-2).

The evaluation routes lie on the teach route of the topometric map (``place.route``): ``drive.follow.routes`` routes
of ``drive.follow.length_m`` starting evenly from its start to that length before its end (one route: the first
``length_m``), each driven with the map of its own stretch of the teach drive, as if taught alone
(:func:`topoloc.drive.closed_loop.repeat_routes`). On every route, for every repeat condition
(``place.repeat_conditions``) and each of ``drive.follow.repeats`` seeds, every agent of ``drive.follow.agents``
(``dlm``: Topo-DLM; ``lp``: Topo-LP; ``replay``: the teach drive's steering per vertex, recorded from the expert's
teach drive of that route) drives it with every localization of ``drive.follow.localization`` (``ground_truth`` or a
place localizer of the registry, with the retrieval network's scores; :mod:`topoloc.drive.closed_loop`), under the
teach drive's speed ahead on the map (``drive.follow.teach_speed_ahead_m``). The same seed gives every agent the same
start offset and odometry noise.

Outputs: ``episodes`` (one row per drive: outcome, progress, localization error, speed of the loop),
``summary`` (success rate per condition and agent, over routes and repeats), ``table`` (like the paper's Tables 1
and 2: success rate per condition and the mean, held-out conditions of the controller's training marked; with several
routes also per route), ``metrics`` (success per agent and route; ``intersections`` and ``shared_m`` summed over the
routes, a stretch counted once per route that holds it), ``paths``
(the driven paths over the map), ``success`` (bars) and ``strip`` (frames of one repeat per condition).
"""

from __future__ import annotations

import logging
from functools import partial
from typing import Any, cast

import numpy as np
import pandas as pd
import torch
from tqdm import tqdm

from topoloc.drive.closed_loop import (
    DLMAgent,
    GroundTruth,
    LPAgent,
    PlaceLocalization,
    RepeatRoute,
    ReplayAgent,
    repeat_routes,
    run_episode,
    speed_limit_ahead,
    teach_controls,
)
from topoloc.drive.controller import AGENT_NAMES, load_controller
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.plot import frame_grid, paths_figure, success_figure
from topoloc.drive.routes import image_shape, make_simulator, place_window, teach_route
from topoloc.drive.topo_lp import CONTROLLERS
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json, write_text
from topoloc.localizer import PLACE_OBSERVATIONS
from topoloc.place.localize import PlaceLocalizer
from topoloc.place.network import load_model
from topoloc.place.topometric_map import TopometricMap
from topoloc.registry import check_names, make
from topoloc.render.conditions import check_conditions

log = logging.getLogger(__name__)



def method_name(agent: str, localization: str) -> str:
    """Table row of an agent with a localization."""
    return f"{AGENT_NAMES[agent]} ({'ground truth' if localization == 'ground_truth' else localization})"


def paper_table(summary: pd.DataFrame, column: str, held_out: list[str], fmt: str) -> str:
    """Markdown: one row per agent, the mean, one column per condition."""
    conditions = list(dict.fromkeys(summary.condition))
    header = ["agent (localization)", "Mean", *[f"{c} (held out)" if c in held_out else c for c in conditions]]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for agent in dict.fromkeys(summary.agent):
        rows = summary[summary.agent == agent].set_index("condition").loc[conditions, column]
        lines.append("| " + " | ".join([agent, fmt.format(rows.mean()), *[fmt.format(v) for v in rows]]) + " |")
    return "\n".join(lines)


def intersections(command: np.ndarray) -> int:
    """Intersections on a stretch of map vertices: the runs of a command other than ``follow`` (index 0)."""
    command = np.asarray(command)
    return int(np.sum((command[1:] != 0) & (command[1:] != command[:-1])) + (len(command) > 0 and command[0] != 0))


def place_localization(name: str, topo: TopometricMap, model: Any, localize: dict[str, Any],
                       window: tuple[slice, slice]) -> PlaceLocalization:
    """A new localization by the registered place localizer ``name`` (on the place images' ``window`` of each image)."""
    return PlaceLocalization(cast(PlaceLocalizer, make(name, PLACE_OBSERVATIONS)), topo, model, localize, window)


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
    controllers = {a: load_controller(inputs[f"controller_{a}"], image_shape(conf), "drive.camera",
                                      CONTROLLERS[a]) for a in follow["agents"] if a in CONTROLLERS}
    retrieval = load_model(inputs["model"]) if place_names else None
    ahead = follow["teach_speed_ahead_m"]
    rows, traces, strips = [], {}, []
    strip_method = (next((a for a in ("lp", "dlm") if a in follow["agents"]), follow["agents"][0]),
                    place_names[0] if place_names else "ground_truth")
    runs = [(c, r, a, loc) for c in names["repeat"] for r in range(int(follow["repeats"]))
            for a in follow["agents"] for loc in localizations]
    progress = tqdm(total=len(parts) * len(runs), desc="repeat drives", unit="drive")
    for k, part in enumerate(parts):
        route, topo, lane_s = part.route, part.topo, part.lane_s
        sim = make_simulator(inputs.get("osm"), graph, route, conf)
        expert = Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
        teach_steer, teach_speed = teach_controls(sim, expert, place["teach_condition"], int(drive["seed"]), lane_s)
        limit = None if ahead is None else speed_limit_ahead(teach_speed, lane_s, float(ahead))
        agents = {"dlm": partial(DLMAgent, controllers.get("dlm"), topo), "lp": partial(LPAgent, controllers.get("lp"), topo),
                  "replay": partial(ReplayAgent, teach_steer, teach_speed, float(drive["expert"]["speed_gain"]))}
        locs = {"ground_truth": partial(GroundTruth, lane_s)}
        for name in place_names:
            locs[name] = partial(place_localization, name, topo, retrieval, place["localize"], place_window(conf))
        for condition, repeat, agent, loc in runs:
            seed = int(np.random.SeedSequence([int(drive["seed"]), 59, names["repeat"].index(condition), repeat, k])
                       .generate_state(1)[0])
            want_strip = k == 0 and repeat == 0 and (agent, loc) == strip_method
            episode = run_episode(sim, agents[agent](), locs[loc](), topo, condition, seed, conf,
                                  int(follow["strip_frames"]) if want_strip else 0, limit)
            key = f"{k}/{condition}/{repeat}/{agent}/{loc}"
            traces[key] = episode.xy
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
    return write_outputs(episodes, traces, strips, parts, graph, conf, held_out, outputs,
                         f"{method_name(*strip_method)}: one repeat drive per condition")


def route_table(episodes: pd.DataFrame) -> str:
    """Markdown: success rate per agent (rows) and evaluation route (columns: where it starts, its intersections, its
    metres on other roads' carriageways)."""
    routes = episodes.drop_duplicates("route").set_index("route").sort_index()
    header = ["agent (localization)", *[f"route {k} ({r.route_start_m:.0f}-{r.route_start_m + r.route_length_m:.0f} m, "
                                        f"{int(r.intersections)} int., {r.route_shared_m:.0f} m shared)" for k, r in routes.iterrows()]]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    rates = episodes.groupby(["agent", "route"], sort=False).success.mean()
    for agent in dict.fromkeys(episodes.agent):
        lines.append("| " + " | ".join([agent, *[f"{rates[agent, k]:.2f}" for k in routes.index]]) + " |")
    return "\n".join(lines)


def write_outputs(episodes: pd.DataFrame, traces: dict[str, np.ndarray], strips: list, parts: list[RepeatRoute],
                  graph: RoadGraph, conf: dict[str, Any], held_out: list[str], outputs: dict[str, str],
                  strip_title: str) -> dict[str, float]:
    """The episode table, summary, tables, figures and metrics of the drives (see the module docstring)."""
    follow, place = conf["drive"]["follow"], conf["place"]
    trained = [str(c) for c in conf["drive"]["demonstrations"]["conditions"]]
    summary = (episodes.groupby(["agent", "condition"], sort=False)
               .agg(success_rate=("success", "mean"), drives=("success", "size"), progress_share=("progress_share", "mean"),
                    mean_loc_error_m=("mean_loc_error_m", "mean"), steps_per_s=("steps_per_s", "mean")).reset_index())
    summary.insert(2, "held_out", summary.condition.isin(held_out))
    with atomic_path(outputs["episodes"]) as tmp:
        episodes.to_csv(tmp, index=False, float_format="%.3f")
    with atomic_path(outputs["summary"]) as tmp:
        summary.to_csv(tmp, index=False, float_format="%.4f")
    steps_per_s = float(episodes.steps.sum() / (episodes.steps / episodes.steps_per_s).sum())
    routes = episodes.drop_duplicates("route")
    facts = {"routes": float(len(parts)), "route_length_m": float(routes.route_length_m.mean()),
             "drives": float(len(episodes)), "steps_per_s": steps_per_s, "intersections": float(routes.intersections.sum()),
             "shared_m": float(routes.route_shared_m.sum())}
    ahead = follow["teach_speed_ahead_m"]
    where = (f"over the first {parts[0].route.length_m:.0f} m of the teach route" if len(parts) == 1 else
             f"on each of {len(parts)} routes of {facts['route_length_m']:.0f} m along the teach route, each with the map "
             "of its own stretch of the teach drive")
    text = [(f"# Route following in closed loop (teach: {place['teach_condition']}; controller trained under "
             f"{', '.join(trained)}; held out: {', '.join(held_out) or 'none'})"), "",
            (f"{int(follow['repeats'])} repeat drive(s) per condition and agent {where}; {steps_per_s:.1f} closed-loop "
             "steps/s on this machine (render, controller, localization). "
             + ("No speed limit from the map. " if ahead is None else
                f"Every agent keeps under the teach drive's speed over the next {float(ahead):g} m of the map. ")
             + (f"{facts['shared_m']:.0f} m of the routes' lanes run on another road's carriageway too (drawn over each "
                "other: the images cannot tell which road the route keeps to).")), ""]
    for title, column, fmt in (("Success rate", "success_rate", "{:.2f}"),
                               ("Share of the route driven", "progress_share", "{:.2f}"),
                               ("Mean localization error (m)", "mean_loc_error_m", "{:.1f}")):
        text += [f"## {title}", "", paper_table(summary, column, held_out, fmt), ""]
    if len(parts) > 1:
        text += ["## Success rate per route (all conditions)", "", route_table(episodes), ""]
    write_text(outputs["table"], "\n".join(text))
    paths_figure(graph, [p.route.xy for p in parts], episodes, traces, outputs["paths"])
    success_figure(summary, outputs["success"], held_out)
    if not strips:
        raise InputError("drive.follow", "no repeat drive was recorded for the frame strip")
    frame_grid(strips, outputs["strip"], strip_title)
    metrics = dict(facts)
    for agent, g in summary.groupby("agent", sort=False):
        short = agent.lower().replace("topo-", "").replace(" (", "_").replace(")", "").replace(" ", "_")
        metrics[f"{short}_success_mean"] = float(g.success_rate.mean())
        metrics[f"{short}_success_min"] = float(g.success_rate.min())
        metrics |= {f"{short}_success_{row.condition}": float(row.success_rate) for row in g.itertuples()}
        if len(parts) > 1:
            per_route = episodes[episodes.agent == agent].groupby("route").success.mean()
            metrics |= {f"{short}_success_route{k}": float(v) for k, v in per_route.items()}
    write_json(outputs["metrics"], metrics)
    return metrics
