"""Route following on maps left out of training: controllers trained on the demonstrations of some maps, checked in
closed loop on random routes of another (issue 39's multi-map target).

Usage (each map a region's results folder with ``graph/graph.graphml`` and ``osm/region.*``; ``build_graph`` makes
them)::

    python -m benchmarks.bench_drive_maps --map helsinki=results/helsinki --map heidelberg=results/heidelberg \\
        --map kitti00=results/kitti00 --case helsinki+heidelberg:kitti00 --case helsinki:kitti00 \\
        [--configfile config/config.yaml --configfile config/experiments/drive_paper.yaml ...] \\
        [--set drive.check.routes=100 ...] [--agent lp] [--seeds 0,1,2] [--workers N] [--train-workers N]
        [--train-only] [--work DIR] [--out FILE]

A case ``TRAIN+TRAIN:TEST`` trains one controller per seed on the named maps' demonstrations pooled
(:meth:`topoloc.drive.demonstrations.Demonstrations.pool`, what ``drive.demonstrations_from`` does in the
pipeline) and checks it on ``drive.check.routes`` random routes of the test map
(:func:`topoloc.drive.on_policy.check_route`, the check of ``train_controller``). The config files are merged in
order (later ones win), then ``--set``. Demonstration routes and check routes are independent of each other, so
they run on ``--workers`` processes; trainings run one after the other, or ``--train-workers`` at once (processes
sharing the GPU), on the configured accelerator (``drive.train.accelerator``: a GPU where there is one). A map's
demonstrations and each trained controller are kept in ``--work`` and reused by a later run with the same settings.

Prints per case and seed the check's success rate, the share of each route driven, the success per condition and
the junctions reached that were taken as commanded (:mod:`topoloc.drive.junctions`: all, and the turns alone), then
each case's mean and spread over the seeds; every junction of every check drive goes to ``<out>.junctions.csv``
(``<out>`` without its ``.md``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc.config import deep_merge, dotted_overrides, load
from topoloc.drive.controller import load_controller
from topoloc.drive.controller_training import fit
from topoloc.drive.demonstrations import Demonstrations, collect_demonstrations, demonstrate_route
from topoloc.drive.junctions import NOT_REACHED, TAKEN, junction_results, roundabout_ways, route_junctions
from topoloc.drive.on_policy import check_metrics, check_route
from topoloc.drive.routes import make_simulator, teach_route
from topoloc.drive.simulator import OUTCOMES
from topoloc.drive.topo_lp import CONTROLLERS
from topoloc.drive.turn_routes import TrainingRoutes
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path

REPO = Path(__file__).resolve().parent.parent
log = logging.getLogger("bench_drive_maps")

#: Per worker process: the config and each map's graph, OSM file and teach route, loaded once.
_STATE: dict[str, Any] = {}


def _init_worker(conf: dict[str, Any], maps: dict[str, str]) -> None:
    torch.set_num_threads(1)
    _STATE.update(conf=conf, maps=maps, loaded={}, graphs={}, roundabouts={}, models={})


def _map(name: str) -> tuple[Any, Any, Any]:
    """The teach route's lane points and the route and simulator makers of map ``name`` (this process's copy)."""
    if name not in _STATE["loaded"]:
        conf, root = _STATE["conf"], Path(_STATE["maps"][name])
        graph = RoadGraph.load(root / "graph" / "graph.graphml")
        osm = next((str(p) for p in sorted((root / "osm").glob("region.*")) if p.suffix != ".json"), None)
        length = float(conf["drive"]["demonstrations"]["route_length_m"])
        _STATE["loaded"][name] = (teach_route(graph, conf).xy,
                                  TrainingRoutes(graph, conf, length),
                                  lambda route, g=graph, o=osm: make_simulator(o, g, route, conf))
        _STATE["graphs"][name] = (graph, osm)
    return _STATE["loaded"][name]


def _demonstrate(task: tuple[str, int]) -> tuple[str, int, Any]:
    name, r = task
    avoid, make_route, make_sim = _map(name)
    return name, r, demonstrate_route(r, _STATE["conf"], avoid, make_route, make_sim)


def _check(task: tuple[str, str, int, str]) -> tuple[str, int, tuple[str, str, float], list[dict[str, Any]]]:
    key, model_path, r, test = task
    conf = _STATE["conf"]
    agent = str(conf["controller"])
    if model_path not in _STATE["models"]:
        _STATE["models"][model_path] = load_controller(model_path, cls=CONTROLLERS[agent]).eval()
    avoid, make_route, make_sim = _map(test)
    made = []  # the route's simulator, for where the drive ended
    row = check_route(r, _STATE["models"][model_path], agent, conf, avoid, make_route,
                      lambda route: made.append(make_sim(route)) or made[-1])
    graph, osm = _STATE["graphs"][test]
    if test not in _STATE["roundabouts"]:  # read from the OSM file of a map that is checked, once per process
        _STATE["roundabouts"][test] = roundabout_ways(osm)
    roundabouts = _STATE["roundabouts"][test]
    jconf = conf["drive"]["follow"]["junctions"]
    sim = made[-1]
    junctions = route_junctions(graph, sim.route, roundabouts, float(jconf["cluster_m"]), float(jconf["around_m"]))
    rows = junction_results(junctions, np.array([sim.s]), np.array([np.nan]), row[1], float(jconf["before_m"]),
                            float(jconf["after_m"]))
    return key, r, row, rows


def digest(value: Any) -> str:
    """A short stable digest of a JSON-able value (the settings a cached file was made with)."""
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()[:10]


def demonstration_paths(names: list[str], conf: dict[str, Any], work: Path) -> dict[str, Path]:
    """Where each map's demonstrations are kept (named by the settings that make them)."""
    key = digest({k: conf[k] for k in ("drive", "place", "render")})
    return {n: work / f"demonstrations_{n}_{key}.npz" for n in names}


def record_demonstrations(names: list[str], conf: dict[str, Any], maps: dict[str, str], work: Path,
                          pool: ProcessPoolExecutor) -> dict[str, Path]:
    """Each map's demonstrations, recorded route by route on the pool unless ``work`` holds them; their files."""
    paths = demonstration_paths(names, conf, work)
    todo = [n for n in names if not paths[n].exists()]
    routes = int(conf["drive"]["demonstrations"]["routes"])
    parts: dict[str, dict[int, Any]] = {n: {} for n in todo}
    started = time.perf_counter()
    for name, r, result in pool.map(_demonstrate, [(n, r) for n in todo for r in range(routes)]):
        parts[name][r] = result
    for name in todo:
        recorded = parts.pop(name)
        rows = [recorded[r] for r in range(routes)]
        avoid = teach_route(RoadGraph.load(Path(maps[name]) / "graph" / "graph.graphml"), conf).xy
        demos, facts = collect_demonstrations([p for row in rows for p in row[0]], [o for row in rows for o in row[1]],
                                              [i for row in rows for i in row[2]], conf, avoid)
        demos.save(paths[name])
        log.info("%s: %d demonstration steps (%s)", name, len(demos), {k: round(v, 3) for k, v in facts.items()})
    if todo:
        log.info("demonstrations of %s: %.0f s", todo, time.perf_counter() - started)
    return paths


def controller_path(case: str, train_maps: list[str], seed: int, conf: dict[str, Any], work: Path) -> Path:
    """Where the controller of ``case`` and ``seed`` is kept (named by the settings that make it)."""
    key = digest({"drive": conf["drive"], "place": conf["place"], "render": conf["render"], "maps": train_maps,
                  "agent": conf["controller"], "seed": seed})
    return work / f"controller_{case.replace('+', '_').replace(':', '-')}_{seed}_{key}.ckpt"


def train(path: Path, train_maps: list[str], seed: int, conf: dict[str, Any],
          demo_paths: dict[str, Path]) -> dict[str, float]:
    """Train the controller at ``path`` on ``train_maps``' demonstrations pooled; its metrics (also beside it)."""
    drive = deep_merge(conf["drive"], {"train": {"seed": seed, "log_model": False}})
    maps = [Demonstrations.load(demo_paths[n]) for n in train_maps]
    pooled = Demonstrations.pool(maps) if len(maps) > 1 else maps[0]
    del maps  # the pooled copy alone while training
    started = time.perf_counter()
    _, _, metrics = fit(drive, pooled, str(path), agent=str(conf["controller"]))
    metrics["wall_seconds"] = time.perf_counter() - started
    path.with_suffix(".json").write_text(json.dumps(metrics))
    log.info("%s: trained in %.0f s (%s)", path.name, metrics["wall_seconds"], metrics.get("best/val/steer_mae"))
    return metrics


def _train_task(task: tuple[Path, list[str], int, dict[str, Any], dict[str, Path]]) -> dict[str, float]:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    return train(*task)


def junction_columns(rows: pd.DataFrame) -> dict[str, float]:
    """The share of the junctions reached that were taken as commanded (:mod:`topoloc.drive.junctions`), over all and
    for the turns (every turn class but ``straight``), and how many were reached."""
    if rows.empty:
        return {"junctions taken": float("nan"), "turns taken": float("nan"), "junctions reached": 0.0}
    reached = rows[rows.result != NOT_REACHED]
    turns = reached[reached.turn != "straight"]
    return {"junctions taken": float((reached.result == TAKEN).mean()) if len(reached) else float("nan"),
            "turns taken": float((turns.result == TAKEN).mean()) if len(turns) else float("nan"),
            "junctions reached": float(len(reached))}


def summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Each case's mean and sample standard deviation over its seeds."""
    out = []
    for case, group in rows.groupby("case", sort=False):
        row: dict[str, Any] = {"case": case, "seed": f"{len(group)} seeds"}
        for column in rows.columns:
            if column in ("case", "seed") or not np.issubdtype(group[column].dtype, np.number):
                continue
            values = group[column].dropna().to_numpy(float)
            spread = values.std(ddof=1) if len(values) > 1 else 0.0
            row[column] = f"{values.mean():.2f} +- {spread:.2f}" if len(values) else "-"
        out.append(row)
    return pd.DataFrame(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--map", action="append", required=True, metavar="NAME=DIR", help="a map: its results folder")
    parser.add_argument("--case", action="append", required=True, metavar="TRAIN+TRAIN:TEST")
    parser.add_argument("--configfile", action="append", default=None, help="merged in order (config/config.yaml)")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="override config keys")
    parser.add_argument("--agent", default="lp", choices=sorted(CONTROLLERS))
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--train-workers", type=int, default=1, help="trainings at once (processes sharing the GPU)")
    parser.add_argument("--train-only", action="store_true", help="record and train, do not check")
    parser.add_argument("--work", default="results/bench_drive_maps", help="demonstrations and controllers, kept")
    add_out_option(parser, "bench_drive_maps")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")

    conf = load(args.configfile or [REPO / "config" / "config.yaml"], dotted_overrides(args.set))
    conf["controller"] = args.agent
    maps = dict(item.split("=", 1) for item in args.map)
    cases = [(c, c.split(":")[0].split("+"), c.split(":")[1]) for c in args.case]
    for case, train_maps, test in cases:
        missing = [n for n in (*train_maps, test) if n not in maps]
        if missing:
            parser.error(f"--case {case}: no --map for {', '.join(missing)}")
    seeds = [int(s) for s in args.seeds.split(",")]
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)

    models = {(case, seed): controller_path(case, train_maps, seed, conf, work) for case, train_maps, _ in cases
              for seed in seeds}
    spawn = multiprocessing.get_context("spawn")  # not forked: the trainings may have started CUDA in this process
    with ProcessPoolExecutor(args.workers, mp_context=spawn, initializer=_init_worker, initargs=(conf, maps)) as pool:
        todo = [(case, train_maps, seed) for case, train_maps, _ in cases for seed in seeds
                if not (models[(case, seed)].exists() and models[(case, seed)].with_suffix(".json").exists())]
        if todo:
            needed = list(dict.fromkeys(n for _, train_maps, _ in todo for n in train_maps))
            demo_paths = record_demonstrations(needed, conf, maps, work, pool)
            tasks = [(models[(case, seed)], train_maps, seed, conf, demo_paths) for case, train_maps, seed in todo]
            started = time.perf_counter()
            if args.train_workers > 1:
                with ProcessPoolExecutor(args.train_workers, mp_context=spawn) as trainers:
                    list(trainers.map(_train_task, tasks))
            else:
                for task in tasks:
                    train(*task)
            log.info("%d trainings: %.0f s", len(tasks), time.perf_counter() - started)
        trained = {k: json.loads(path.with_suffix(".json").read_text()) for k, path in models.items()}
        if args.train_only:
            return 0
        routes = int(conf["drive"]["check"]["routes"])
        tasks = [(f"{case}|{seed}", str(models[(case, seed)]), r, test)
                 for case, _, test in cases for seed in seeds for r in range(routes)]
        started = time.perf_counter()
        checked: dict[str, list[tuple[int, Any]]] = {}
        junctions: dict[str, list[dict[str, Any]]] = {}
        for key, r, row, rows in pool.map(_check, tasks):
            checked.setdefault(key, []).append((r, row))
            junctions.setdefault(key, []).extend(rows)
        log.info("checks: %d routes in %.0f s", len(tasks), time.perf_counter() - started)

    rows = []
    for case, _, test in cases:
        for seed in seeds:
            metrics = check_metrics([row for _, row in sorted(checked[f"{case}|{seed}"])])
            rows.append({"case": case, "seed": seed,
                         "val steer MAE": trained[(case, seed)].get("best/val/steer_mae", float("nan")),
                         **{k.removeprefix("check/"): v for k, v in metrics.items() if k != "check/routes"},
                         **junction_columns(pd.DataFrame(junctions[f"{case}|{seed}"]))})
    table = pd.DataFrame(rows)
    counts = [c for c in table.columns if c.startswith("success_") or c in OUTCOMES]
    table[counts] = table[counts].fillna(0.0)  # a condition or failure a seed did not meet: none of it
    text = (f"{args.agent}, {routes} check routes per case and seed\n\n"
            + table.to_markdown(index=False, floatfmt=".2f")
            + "\n\n" + summary(table).to_markdown(index=False))
    with markdown_copy(args.out):
        print(text)
    junction_rows = pd.DataFrame([{"case": key.split("|")[0], "seed": int(key.split("|")[1]), **row}
                                  for key, rows in junctions.items() for row in rows])
    with atomic_path(Path(args.out).with_suffix(".junctions.csv")) as tmp:
        junction_rows.to_csv(tmp, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
