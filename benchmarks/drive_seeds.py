"""One controller config over several training seeds: the closed-loop check and teach and repeat, one row per seed.

A success rate of the teach route moves with one hard turn taken or missed, and which turns a controller takes moves
with its training seed. This script trains the same controller (``train_controller.run``, the check included) once
per seed on the training region's demonstrations, runs the same check on unseen routes of the test region, drives
the test region's teach route with each (``follow_route.run``, that controller alone), and prints one row per seed
and the mean over the seeds: per condition, then per route of the teach route. The two checks are the independent
figures (their routes choose nothing); the teach route's figure is the paper's.

Usage (after the paper-sized run built the training region's demonstrations and the test region's topometric map;
see the README, "Route following")::

    PYTHONPATH=src python benchmarks/drive_seeds.py --agent lp --seeds 0 1 2 3 4 \\
        --train config/config.yaml --test config/regions/kitti00.yaml --also config/experiments/drive_paper.yaml

Everything is written under ``--out`` (default ``results/seeds/<train region>-<test region>/<agent>``), one folder
per seed; a checkpoint, check or teach-and-repeat result already there is not made again, so a killed run picks up
where it stopped (to evaluate a controller trained elsewhere, copy its ``controller.ckpt`` and ``metrics.json`` to
``seed<k>/train/``). The test region's teach route is localized with the training region's retrieval network, so its
topometric map must have been built with it: the paper's protocol, ``config/experiments/drive_transfer.yaml``. With ``--test``
the same as ``--train`` it is the training region's own teach route and no second check.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from topoloc.config import deep_merge, load_layered
from topoloc.drive import controller_training, follow_route, train_controller
from topoloc.drive.controller import load_controller
from topoloc.drive.topo_lp import CONTROLLERS
from topoloc.io import write_json
from topoloc.osm.download_osm import raw_osm_suffix


def require(path: Path, made_by: str) -> str:
    """``path`` as a string; one line naming it and the rule that makes it when it is missing."""
    if not path.exists():
        raise SystemExit(f"{path}: missing (made by the rule {made_by}; run the paper-sized pipeline first)")
    return str(path)


def osm_input(conf: dict[str, Any]) -> str:
    """The region's OSM file as ``download_osm`` writes it (``raw_osm_suffix`` of ``conf['region']``)."""
    region = conf["region"]
    return require(Path("results") / region["name"] / "osm" / f"region{raw_osm_suffix(region)}", "download_osm")


def train_seed(conf: dict[str, Any], agent: str, seed: int, out: Path, demonstrations: Path | None = None) -> dict[str, float]:
    """Train ``agent`` with ``drive.train.seed = seed`` (and its check) into ``out``, unless already there, on
    ``demonstrations`` (default: the pipeline's of ``conf``'s region)."""
    metrics = out / "metrics.json"
    if (out / "controller.ckpt").exists() and metrics.exists():
        return json.loads(metrics.read_text())
    region = conf["region"]["name"]
    conf = deep_merge(conf, {"controller": agent, "drive": {"train": {"seed": seed, "log_model": False}}})
    demonstrations = demonstrations or Path("results") / region / "drive" / "demonstrations.npz"
    inputs = {"demonstrations": require(demonstrations, "simulate_demonstrations"),
              "graph": require(Path("results") / region / "graph" / "graph.graphml", "build_graph"),
              "osm": osm_input(conf)}
    outputs = {"model": out / "controller.ckpt", "history": out / "history.csv", "metrics": metrics,
               "figure": out / "training.png"}
    return train_controller.run(conf, inputs, {k: str(v) for k, v in outputs.items()})


def check_seed(conf: dict[str, Any], agent: str, controller: Path, out: Path) -> dict[str, float]:
    """The closed-loop check (``controller_training.check_controller``) of ``controller`` on unseen routes of ``conf``'s region, written
    to the JSON file ``out``, unless already there."""
    if out.exists():
        return json.loads(out.read_text())
    region = conf["region"]["name"]
    inputs = {"graph": require(Path("results") / region / "graph" / "graph.graphml", "build_graph"),
              "osm": osm_input(conf)}
    torch.set_num_threads(int(conf["drive"]["threads"]))
    model = load_controller(controller, cls=CONTROLLERS[agent])
    metrics = controller_training.check_controller(deep_merge(conf, {"controller": agent}), inputs, model)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(out, metrics)
    return metrics


def follow_seed(conf: dict[str, Any], agent: str, controller: Path, retrieval: str, out: Path) -> dict[str, float]:
    """Drive the teach route of ``conf``'s region with ``controller`` alone (``follow_route.run``) into ``out``."""
    metrics = out / "metrics.json"
    if metrics.exists():
        return json.loads(metrics.read_text())
    region = conf["region"]["name"]
    conf = deep_merge(conf, {"drive": {"follow": {"agents": [agent]}}})
    root = Path("results") / region
    inputs = {"osm": osm_input(conf), "graph": require(root / "graph" / "graph.graphml", "build_graph"),
              f"controller_{agent}": str(controller), "model": retrieval,
              "map": require(root / "topometric_map" / "map.npz", "build_topometric_map")}
    out.mkdir(parents=True, exist_ok=True)
    names = {"episodes": "episodes.csv", "summary": "summary.csv", "metrics": "metrics.json", "table": "tables.md",
             "paths": "paths.png", "success": "success.png", "strip": "strip.png"}
    return follow_route.run(conf, inputs, {k: str(out / v) for k, v in names.items()})


def table(rows: list[dict[str, Any]], agent: str, localizations: list[str], columns: list[str]) -> str:
    """Markdown: per seed, its checks' success rates (``checks``: region -> rate) and, per localization, the teach
    route's success ``columns`` (suffixes of ``follow_route``'s metrics: ``mean``, ``min``, a condition,
    ``route<k>``); then the mean over the seeds."""
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
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", choices=["dlm", "lp"], default="lp")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--train", default="config/config.yaml", help="the training region's config")
    parser.add_argument("--test", default="config/regions/kitti00.yaml", help="the config of the region whose teach route is driven")
    parser.add_argument("--also", nargs="*", default=["config/experiments/drive_paper.yaml"],
                        help="config files merged over both (later ones win)")
    parser.add_argument("--out", type=Path, help="output folder (default results/seeds/<train>-<test>/<agent>)")
    parser.add_argument("--demonstrations", type=Path,
                        help="the training region's demonstrations, when --also changes what they hold (such as "
                             "drive.camera) from the pipeline's (default results/<train>/drive/demonstrations.npz)")
    args = parser.parse_args()
    train_conf, test_conf = load_layered(args.train, args.also), load_layered(args.test, args.also)
    train_region, test_region = train_conf["region"]["name"], test_conf["region"]["name"]
    out = args.out or Path("results") / "seeds" / f"{train_region}-{test_region}" / args.agent
    retrieval = require(Path("results") / train_region / "retrieval" / "model.ckpt", "train_retrieval")
    rows = []
    for seed in args.seeds:
        here = out / f"seed{seed}"
        trained = train_seed(train_conf, args.agent, seed, here / "train", args.demonstrations)
        checks = {train_region: trained.get("check/success_rate", np.nan)}
        if test_region != train_region:
            tested = check_seed(test_conf, args.agent, here / "train" / "controller.ckpt", here / "check_test.json")
            checks[test_region] = tested["check/success_rate"]
        followed = follow_seed(test_conf, args.agent, here / "train" / "controller.ckpt", retrieval, here / "follow")
        rows.append({"seed": seed, "checks": checks, "follow": followed})
        print(f"seed {seed}: " + ", ".join(f"check {k} {v:.2f}" for k, v in checks.items()) + ", " + ", ".join(
            f"{k.removeprefix(args.agent + '_')} {v:.2f}" for k, v in followed.items() if k.endswith("_success_mean")),
            flush=True)
    localizations = [str(n) for n in test_conf["drive"]["follow"]["localization"]]
    conditions = [str(c) for c in test_conf["place"]["repeat_conditions"]]
    routes = sorted({k.rsplit("_", 1)[1] for row in rows for k in row["follow"] if "_success_route" in k},
                    key=lambda name: int(name.removeprefix("route")))
    report = (f"Success per condition\n\n{table(rows, args.agent, localizations, ['mean', 'min', *conditions])}\n\n"
              f"Success per route of the teach route\n\n{table(rows, args.agent, localizations, routes)}")
    (out / "seeds.md").write_text(report + "\n")
    print(report)


if __name__ == "__main__":
    main()
