"""The report of the repeat drives of ``follow_route``: the episode table, the summary per agent and condition, the
tables like Cai & Wan's Tables 1 and 2 (and per route), the figures and the metrics."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from topoloc.drive.junctions import KINDS, NOT_REACHED, TAKEN, TURNS, junction_rates
from topoloc.drive.plot import frame_grid, junction_figure, paths_figure, success_figure
from topoloc.drive.repeat_routes import RepeatRoute
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json, write_text
from topoloc.report_tables import condition_table, markdown_table


def route_table(episodes: pd.DataFrame) -> str:
    """Markdown: success rate per agent (rows) and evaluation route (columns: where it starts, its intersections, its
    metres on other roads' carriageways)."""
    routes = episodes.drop_duplicates("route").set_index("route").sort_index()
    header = ["agent (localization)", *[f"route {k} ({r.route_start_m:.0f}-{r.route_start_m + r.route_length_m:.0f} m, "
                                        f"{int(r.intersections)} int., {r.route_shared_m:.0f} m shared)" for k, r in routes.iterrows()]]
    rates = episodes.groupby(["agent", "route"], sort=False).success.mean()
    return markdown_table(header, [[agent, *[f"{rates[agent, k]:.2f}" for k in routes.index]]
                                   for agent in dict.fromkeys(episodes.agent)])


def _short(agent: str) -> str:
    """The metric name prefix of a table row, e.g. ``lp_place_loop`` for "Topo-LP (place_loop)"."""
    return agent.lower().replace("topo-", "").replace(" (", "_").replace(")", "").replace(" ", "_")


def _rate_table(table: pd.DataFrame, header: str) -> str:
    """Markdown of a :func:`~topoloc.drive.junctions.junction_rates` frame: "share (reached)" per cell."""
    rate, reached = table["rate"], table["reached"]
    rows = [[agent, *[f"{rate.at[agent, c]:.2f} ({int(reached.at[agent, c])})" if reached.at[agent, c] == reached.at[agent, c]
                      else "-" for c in rate.columns]] for agent in rate.index]
    return markdown_table([header, *rate.columns], rows)


def junction_section(junctions: pd.DataFrame) -> tuple[list[str], dict[str, pd.DataFrame]]:
    """The markdown section of the junction benchmark and its rate tables by turn class and by kind."""
    rates = {"turn": junction_rates(junctions, "turn", TURNS), "kind": junction_rates(junctions, "kind", KINDS)}
    routes = junctions.drop_duplicates(["route", "junction"])
    text = ["## Junctions taken as commanded", "",
            (f"{len(routes)} junction(s) on the route(s) ({', '.join(f'{n} {k}' for k, n in routes.kind.value_counts().items())}); "
             "per agent the share of the junctions reached that the drive took as commanded (got past without leaving "
             "the route's roads), and in brackets how many were reached, over all conditions and repeats. "
             "The expert sees the true state: its failures are the lane's or the vehicle's, not the controller's."), "",
            "### By turn", "", _rate_table(rates["turn"], "agent (localization)"), "",
            "### By kind", "", _rate_table(rates["kind"], "agent (localization)"), ""]
    return text, rates


def write_follow_report(episodes: pd.DataFrame, traces: dict[str, np.ndarray], strips: list, parts: list[RepeatRoute],
                        graph: RoadGraph, conf: dict[str, Any], held_out: list[str], outputs: dict[str, str],
                        strip_title: str, junctions: pd.DataFrame) -> dict[str, float]:
    """Write the outputs of :mod:`topoloc.drive.follow_route` from its drives (episode table, summary, tables, figures
    and metrics; ``junctions``: the rows of :func:`topoloc.drive.junctions.junction_results` of every drive); return
    the metrics."""
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
        text += [f"## {title}", "", condition_table(summary, "agent", column, held_out, fmt, "agent (localization)"), ""]
    if len(parts) > 1:
        text += ["## Success rate per route (all conditions)", "", route_table(episodes), ""]
    if len(junctions):
        section, rates = junction_section(junctions)
        text += section
        junction_figure(rates, outputs["junction_figure"])
    else:
        text += ["## Junctions taken as commanded", "", "The route(s) pass no junction.", ""]
        junction_figure({}, outputs["junction_figure"])
    with atomic_path(outputs["junctions"]) as tmp:
        junctions.to_csv(tmp, index=False, float_format="%.2f")
    write_text(outputs["table"], "\n".join(text))
    paths_figure(graph, [p.route.xy for p in parts], episodes, traces, outputs["paths"])
    success_figure(summary, outputs["success"], held_out)
    if not strips:
        raise InputError("drive.follow", "no repeat drive was recorded for the frame strip")
    frame_grid(strips, outputs["strip"], strip_title)
    metrics = dict(facts)
    for agent, g in summary.groupby("agent", sort=False):
        short = _short(agent)
        metrics[f"{short}_success_mean"] = float(g.success_rate.mean())
        metrics[f"{short}_success_min"] = float(g.success_rate.min())
        metrics |= {f"{short}_success_{row.condition}": float(row.success_rate) for row in g.itertuples()}
        if len(parts) > 1:
            per_route = episodes[episodes.agent == agent].groupby("route").success.mean()
            metrics |= {f"{short}_success_route{k}": float(v) for k, v in per_route.items()}
    if len(junctions):
        reached = junctions[junctions.result != NOT_REACHED]
        metrics["junctions"] = float(len(junctions.drop_duplicates(["route", "junction"])))
        for agent, g in reached.groupby("agent", sort=False):
            short = _short(agent)
            metrics[f"{short}_junction_success"] = float((g.result == TAKEN).mean())
            metrics[f"{short}_junctions_reached"] = float(len(g))
    write_json(outputs["metrics"], metrics)
    return metrics
