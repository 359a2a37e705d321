"""Experiment ``drive_seeds``: one controller config over several training seeds, one row per seed.

A success rate of the teach route moves with one hard turn taken or missed, and which turns a controller takes moves
with its training seed. Per seed (wildcard ``{seed}``) the rule ``train_controller_seed`` trains the same controller
(the ``train_controller`` stage with ``drive.train.seed`` set to the seed, its closed-loop check on unseen routes
included) and ``follow_route_seed`` drives the region's teach route with it alone (the ``follow_route`` stage). This
module's :func:`summarize` gathers them: per seed the check's success rate and, per localization, the teach route's
success per condition and per route, then the mean and the spread over the seeds. The check is the independent
figure (its routes choose nothing); the teach route's is the paper's.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from topoloc.io import write_json, write_text


def table(rows: list[dict[str, Any]], agent: str, localizations: list[str], columns: list[str]) -> str:
    """Markdown: per seed, its checks' success rates (``checks``: region -> rate) and, per localization, the teach
    route's success ``columns`` (suffixes of ``follow_route``'s metrics: ``mean``, ``min``, a condition,
    ``route<k>``); then the mean and the sample standard deviation over the seeds."""
    checks = list(rows[0]["checks"]) if rows else []
    head = ["seed", *[f"check {name}" for name in checks]] + [f"{loc} {c}" for loc in localizations for c in columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    values = []
    for row in rows:
        v = [row["checks"].get(name, np.nan) for name in checks]
        v += [row["follow"].get(f"{agent}_{loc}_success_{c}", np.nan) for loc in localizations for c in columns]
        values.append(v)
        lines.append(f"| {row['seed']} | " + " | ".join(f"{x:.2f}" for x in v) + " |")
    lines.append("| **mean** | " + " | ".join(f"**{x:.2f}**" for x in np.nanmean(values, axis=0)) + " |")
    if len(values) > 1:
        lines.append("| sd | " + " | ".join(f"{x:.2f}" for x in np.nanstd(values, axis=0, ddof=1)) + " |")
    return "\n".join(lines)


def seed_rows(conf: dict[str, Any], inputs: dict[str, str]) -> list[dict[str, Any]]:
    """Per seed of ``experiments.drive_seeds.seeds``: its check (input ``train_<seed>``, ``train_controller``'s
    metrics) and teach-and-repeat figures (input ``follow_<seed>``, ``follow_route``'s metrics)."""
    region = conf["region"]
    rows = []
    for seed in conf["drive_seeds"]["seeds"]:
        trained = json.loads(Path(inputs[f"train_{seed}"]).read_text())
        followed = json.loads(Path(inputs[f"follow_{seed}"]).read_text())
        rows.append({"seed": seed, "checks": {region: trained.get("check/success_rate", np.nan)}, "follow": followed})
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
    sentence = (f"The {agent} controller trained once per seed ({seeds}) on the demonstrations of {conf['region']}, "
                f"each checked on unseen routes and driven alone on the teach route (success per localization and "
                f"condition); then the mean and the sample standard deviation over the seeds.")
    write_text(outputs["summary"], f"## Route following over training seeds\n\n{sentence}\n\n"
                                   f"{table(rows, agent, localizations, ['mean', 'min', *conditions])}\n")
    write_text(outputs["routes"], f"## Route following over training seeds, per route of the teach route\n\n"
                                  f"{table(rows, agent, localizations, routes)}\n")
    keys = sorted({k for row in rows for k in row["follow"] if "_success_" in k})
    means = {k: float(np.nanmean([row["follow"].get(k, np.nan) for row in rows])) for k in keys}
    means[f"check/{conf['region']}"] = float(np.nanmean([row["checks"][conf["region"]] for row in rows]))
    write_json(outputs["json"], {"agent": agent, "seeds": [row["seed"] for row in rows],
                                 "rows": [{"seed": r["seed"], "checks": r["checks"],
                                           "follow": {k: r["follow"].get(k) for k in keys}} for r in rows],
                                 "mean": means})
    return {f"{k}_mean": v for k, v in means.items() if np.isfinite(v)}
