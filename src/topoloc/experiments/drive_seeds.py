"""Experiment ``drive_seeds``: one controller config over several training seeds, one row per seed.

A success rate of the teach route moves with one hard turn taken or missed, and which turns a controller takes moves
with its training seed. Per seed (wildcard ``{seed}``) the rule ``train_controller_seed`` trains the same controller
(the ``train_controller`` stage with ``drive.train.seed`` set to the seed, its closed-loop check on unseen routes
included) and ``follow_route_seed`` drives the region's teach route with it alone (the ``follow_route`` stage). When
the controllers come from another region (``drive.controllers_from``), :func:`run` (rule ``check_controller_seed``)
runs the same closed-loop check on unseen routes of this region too. :func:`summarize` gathers them: per seed the
checks' success rates and, per localization, the teach route's success per condition and per route, then the mean and
the spread over the seeds. The checks are the independent figures (their routes choose nothing); the teach route's is
the paper's.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from topoloc.drive.on_policy import closed_loop_check
from topoloc.drive.routes import make_simulator, random_drive_route, teach_route
from topoloc.drive.topo_lp import load_controller
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import write_json, write_text
from topoloc.report_tables import markdown_table


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """The closed-loop check of the controller ``inputs['controller']`` (``conf['controller']``, dlm or lp) on unseen
    routes of this region (``graph``, ``osm``), as ``train_controller`` checks on its own region; ``metrics`` (JSON)."""
    torch.set_num_threads(int(conf["drive"]["threads"]))
    model = load_controller(inputs["controller"])
    graph = RoadGraph.load(inputs["graph"])
    length = float(conf["drive"]["demonstrations"]["route_length_m"])
    metrics = closed_loop_check(model.eval(), conf, teach_route(graph, conf).xy,
                                lambda rng: random_drive_route(graph, conf, length, rng),
                                lambda route: make_simulator(inputs.get("osm"), graph, route, conf))
    write_json(outputs["metrics"], metrics)
    return metrics


def table(rows: list[dict[str, Any]], agent: str, localizations: list[str], columns: list[str]) -> str:
    """Markdown: per seed, its checks' success rates (``checks``: region -> rate) and, per localization, the teach
    route's success ``columns`` (suffixes of ``follow_route``'s metrics: ``mean``, ``min``, a condition,
    ``route<k>``); then the mean and the sample standard deviation over the seeds."""
    checks = list(rows[0]["checks"]) if rows else []
    head = ["seed", *[f"check {name}" for name in checks]] + [f"{loc} {c}" for loc in localizations for c in columns]
    values, cells = [], []
    for row in rows:
        v = [row["checks"].get(name, np.nan) for name in checks]
        v += [row["follow"].get(f"{agent}_{loc}_success_{c}", np.nan) for loc in localizations for c in columns]
        values.append(v)
        cells.append([str(row["seed"]), *(f"{x:.2f}" for x in v)])
    cells.append(["**mean**", *(f"**{x:.2f}**" for x in np.nanmean(values, axis=0))])
    if len(values) > 1:
        cells.append(["sd", *(f"{x:.2f}" for x in np.nanstd(values, axis=0, ddof=1))])
    return markdown_table(head, cells)


def seed_rows(conf: dict[str, Any], inputs: dict[str, str]) -> list[dict[str, Any]]:
    """Per seed of ``experiments.drive_seeds.seeds``: its check on unseen routes of the training region
    (``conf['train_region']``; input ``train_<seed>``, ``train_controller``'s metrics), on those of this region when
    the controllers came from another (input ``check_<seed>``, :func:`run`'s metrics), and its teach-and-repeat
    figures (input ``follow_<seed>``, ``follow_route``'s metrics)."""
    rows = []
    for seed in conf["drive_seeds"]["seeds"]:
        trained = json.loads(Path(inputs[f"train_{seed}"]).read_text())
        followed = json.loads(Path(inputs[f"follow_{seed}"]).read_text())
        checks = {conf["train_region"]: trained.get("check/success_rate", np.nan)}
        if f"check_{seed}" in inputs:  # the controllers came from another region: its check here too
            checks[conf["region"]] = json.loads(Path(inputs[f"check_{seed}"]).read_text())["check/success_rate"]
        rows.append({"seed": seed, "checks": checks, "follow": followed})
    return rows


def summarize(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """``summary`` (markdown: success per condition), ``routes`` (markdown: per route of the teach route) and
    ``json`` (every seed's figures and their means)."""
    agent = conf["drive_seeds"]["agent"]
    rows = seed_rows(conf, inputs)
    localizations = [str(n) for n in conf["localization"]]
    conditions = [str(c) for c in conf["conditions"]]
    routes = sorted({k.rsplit("_", 1)[1] for row in rows for k in row["follow"] if "_success_route" in k},
                    key=lambda name: int(name.removeprefix("route")))
    seeds = ", ".join(str(row["seed"]) for row in rows)
    sentence = (f"The {agent} controller trained once per seed ({seeds}) on the demonstrations of {conf['train_region']}, "
                f"each checked on unseen routes there and driven alone on the teach route of {conf['region']} (success "
                f"per localization and condition); then the mean and the sample standard deviation over the seeds.")
    write_text(outputs["summary"], f"## Route following over training seeds\n\n{sentence}\n\n"
                                   f"{table(rows, agent, localizations, ['mean', 'min', *conditions])}\n")
    write_text(outputs["routes"], f"## Route following over training seeds, per route of the teach route\n\n"
                                  f"{table(rows, agent, localizations, routes)}\n")
    keys = sorted({k for row in rows for k in row["follow"] if "_success_" in k})
    means = {k: float(np.nanmean([row["follow"].get(k, np.nan) for row in rows])) for k in keys}
    for region in rows[0]["checks"] if rows else []:
        means[f"check/{region}"] = float(np.nanmean([row["checks"][region] for row in rows]))
    write_json(outputs["json"], {"agent": agent, "seeds": [row["seed"] for row in rows],
                                 "rows": [{"seed": r["seed"], "checks": r["checks"],
                                           "follow": {k: r["follow"].get(k) for k in keys}} for r in rows],
                                 "mean": means})
    return {f"{k}_mean": v for k, v in means.items() if np.isfinite(v)}
