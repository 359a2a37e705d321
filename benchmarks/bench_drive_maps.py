"""Route following on maps left out of training: controllers trained on the demonstrations of some maps, checked in
closed loop on random routes of another (issue 39's multi-map target).

Usage (each map a region's results folder with ``graph/graph.graphml`` and ``osm/region.*``; ``build_graph`` makes
them)::

    python -m benchmarks.bench_drive_maps --map helsinki=results/helsinki --map heidelberg=results/heidelberg \\
        --map kitti00=results/kitti00 --case helsinki+heidelberg:kitti00 --case helsinki:kitti00 \\
        [--configfile config/config.yaml --configfile config/experiments/drive_paper.yaml ...] \\
        [--set drive.check.routes=100 ...] [--agent lp] [--seeds 0,1,2] [--workers N] [--train-workers N]
        [--train-only] [--teach-repeat ground_truth,place_loop --retrieval CKPT] [--route-length-m 300,500]
        [--work DIR] [--out FILE]

A case ``TRAIN+TRAIN:TEST`` trains one controller per seed on the named maps' demonstrations pooled
(:meth:`topoloc.drive.demonstrations.Demonstrations.pool`, what ``drive.demonstrations_from`` does in the
pipeline) and checks it on ``drive.check.routes`` random routes of the test map
(:func:`topoloc.drive.on_policy.check_route`, the check of ``train_controller``). The config files are merged in
order (later ones win), then ``--set``. Demonstration routes and check routes are independent of each other, so
they run on ``--workers`` processes; trainings run one after the other, or ``--train-workers`` at once (processes
sharing the GPU), on the configured accelerator (``drive.train.accelerator``: a GPU where there is one). A map's
demonstrations and each trained controller are kept in ``--work`` and reused by a later run with the same settings.
Check routes are as long as the demonstrations' (``drive.demonstrations.route_length_m``), or with
``--route-length-m MIN,MAX`` each as long as drawn evenly between the two (:func:`check_length`: route ``r`` has the
same length on every map and seed, so the controllers are checked on equal terms).

With ``--teach-repeat``, each check route is taught and repeated as ``follow_route`` does on the teach route: the
expert's teach drive under ``place.teach_condition`` gives the route's topometric map in memory
(:func:`topoloc.drive.taught_routes.teach_map`, embedded by the ``--retrieval`` network), and the controller drives
it with each localization named (``ground_truth`` or a place localizer of the registry), an aligned Topo-LP with its
pose tracker on the teach drive's images, under the teach drive's speed ahead; the rows then carry a
``localization`` column, and routes whose teach drive the expert did not finish are left out (``untaught``).

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

from benchmarks.markdown import add_out_option, markdown_copy, seed_list
from topoloc.config import deep_merge, dotted_overrides, load
from topoloc.drive.agents import TeachImages, controller_agent
from topoloc.drive.controller_training import fit
from topoloc.drive.demonstrations import (
    Demonstrations,
    collect_demonstrations,
    demonstrate_route,
    training_route,
)
from topoloc.drive.episodes import run_episode, speed_limit_ahead
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.follow_route import place_localization
from topoloc.drive.junctions import (
    NOT_REACHED,
    TAKEN,
    junction_results,
    roundabout_ways,
    route_junctions,
)
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.on_policy import CHECK_STREAM, check_metrics, check_route
from topoloc.drive.routes import make_simulator, teach_route
from topoloc.drive.simulator import OUTCOMES, SUCCESS
from topoloc.drive.taught_routes import teach_map
from topoloc.drive.topo_lp import CONTROLLERS, load_controller
from topoloc.drive.turn_routes import TrainingRoutes
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.localizer import PLACE_OBSERVATIONS
from topoloc.place.network import load_model
from topoloc.registry import check_names

REPO = Path(__file__).resolve().parent.parent
log = logging.getLogger("bench_drive_maps")

#: Per worker process: the config and each map's graph, OSM file and teach route, loaded once.
_STATE: dict[str, Any] = {}


def _init_worker(conf: dict[str, Any], maps: dict[str, str], retrieval: str | None = None,
                 check_length_m: tuple[float, float] | None = None) -> None:
    torch.set_num_threads(1)
    _STATE.update(conf=conf, maps=maps, loaded={}, graphs={}, roundabouts={}, models={}, retrieval=retrieval,
                  check_length_m=check_length_m, check_routes={})


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


def check_length(r: int, seed: int, length_m: tuple[float, float]) -> float:
    """Check route ``r``'s length (m): drawn evenly in ``length_m`` (its own stream, the same for every map, training
    seed and run), to the metre."""
    low, high = length_m
    rng = np.random.default_rng([int(seed), CHECK_STREAM, int(r), 1])
    return float(round(low + (high - low) * rng.random()))


def _check_routes(name: str, r: int) -> Any:
    """The maker of check route ``r`` of map ``name``: the demonstrations' (their route length), or one of a length
    drawn by :func:`check_length` with ``--route-length-m``."""
    _, make_route, _ = _map(name)
    lengths = _STATE["check_length_m"]
    if lengths is None:
        return make_route
    length = check_length(r, int(_STATE["conf"]["drive"]["seed"]), lengths)
    key = (name, length)
    if key not in _STATE["check_routes"]:
        _STATE["check_routes"][key] = TrainingRoutes(make_route.graph, _STATE["conf"], length)
    return _STATE["check_routes"][key]


def _demonstrate(task: tuple[str, int]) -> tuple[str, int, Any]:
    name, r = task
    avoid, make_route, make_sim = _map(name)
    return name, r, demonstrate_route(r, _STATE["conf"], avoid, make_route, make_sim)


def _controller(model_path: str) -> Any:
    """The controller at ``model_path`` (this process's copy, loaded once)."""
    if model_path not in _STATE["models"]:
        _STATE["models"][model_path] = load_controller(model_path).eval()
    return _STATE["models"][model_path]


def _junctions(test: str, sim: Any) -> list[Any]:
    """The junctions of ``sim``'s route on map ``test`` (its roundabouts read from the OSM file once per process)."""
    graph, osm = _STATE["graphs"][test]
    if test not in _STATE["roundabouts"]:
        _STATE["roundabouts"][test] = roundabout_ways(osm)
    jconf = _STATE["conf"]["drive"]["follow"]["junctions"]
    return route_junctions(graph, sim.route, _STATE["roundabouts"][test], float(jconf["cluster_m"]), float(jconf["around_m"]))


def _check(task: tuple[str, str, int, str]) -> tuple[str, int, tuple[str, str, float], list[dict[str, Any]]]:
    key, model_path, r, test = task
    conf = _STATE["conf"]
    avoid, _, make_sim = _map(test)
    made = []  # the route's simulator, for where the drive ended
    row = check_route(r, _controller(model_path), conf, avoid, _check_routes(test, r),
                      lambda route: made.append(make_sim(route)) or made[-1])
    sim = made[-1]
    jconf = conf["drive"]["follow"]["junctions"]
    rows = junction_results(_junctions(test, sim), np.array([sim.s]), np.array([np.nan]), row[1],
                            float(jconf["before_m"]), float(jconf["after_m"]))
    return key, r, row, rows


def _teach_repeat(task: tuple[str, str, int, str, list[str]]) -> tuple[str, int, dict[str, Any] | None]:
    """Check route ``r`` of map ``test`` taught and repeated (see the module docstring): per localization the check's
    row (condition, outcome, share driven), the junction rows and the mean localization error; None when the expert
    did not finish the teach drive."""
    key, model_path, r, test, localizations = task
    conf = _STATE["conf"]
    drive, place = conf["drive"], conf["place"]
    if "retrieval_model" not in _STATE:
        _STATE["retrieval_model"] = load_model(_STATE["retrieval"])
    retrieval, controller = _STATE["retrieval_model"], _controller(model_path)
    avoid, _, make_sim = _map(test)
    route = training_route(r, conf, avoid, _check_routes(test, r), stream=CHECK_STREAM)  # the check's route r
    sim = make_sim(route)
    conditions = [str(c) for c in place["repeat_conditions"]]
    condition = conditions[r % len(conditions)]
    seed = int(np.random.SeedSequence([int(drive["seed"]), CHECK_STREAM, r]).generate_state(1)[0])
    taught = teach_map(sim, Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"])), retrieval, conf, seed)
    if taught.outcome != SUCCESS:
        return key, r, None
    ahead = drive["follow"]["teach_speed_ahead_m"]
    limit = None if ahead is None else speed_limit_ahead(taught.teach_speed, taught.lane_s, float(ahead))
    teach = TeachImages(sim, taught.topo, str(place["teach_condition"]), seed, bool(place["image"]["color"]))
    junctions, jconf = _junctions(test, sim), drive["follow"]["junctions"]
    out = {}
    for name in localizations:
        driver = controller_agent(controller, taught.topo, teach)
        localization = (GroundTruth(taught.lane_s) if name == "ground_truth"
                        else place_localization(name, taught.topo, retrieval, conf))
        episode = run_episode(sim, driver, localization, taught.topo, condition, seed, conf, 0, limit)
        share = min(1.0, episode.progress_m / max(route.length_m - sim.spec.goal_m, 1e-9))
        rows = junction_results(junctions, episode.s, episode.speed, episode.outcome, float(jconf["before_m"]),
                                float(jconf["after_m"]))
        out[name] = ((condition, episode.outcome, share), rows, float(np.mean(episode.loc_error_m)))
    return key, r, out


def digest(value: Any) -> str:
    """A short stable digest of a JSON-able value (the settings a cached file was made with)."""
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()[:10]


def training_settings(conf: dict[str, Any]) -> dict[str, Any]:
    """The settings demonstrations and trainings depend on: ``drive`` but what checks and repeat drives use
    (``check``, ``follow``), ``place``, ``render``."""
    drive = {k: v for k, v in conf["drive"].items() if k not in ("check", "follow")}
    return {"drive": drive, "place": conf["place"], "render": conf["render"]}


def demonstration_paths(names: list[str], conf: dict[str, Any], work: Path) -> dict[str, Path]:
    """Where each map's demonstrations are kept (named by the settings that make them)."""
    key = digest(training_settings(conf))
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
    key = digest({**training_settings(conf), "maps": train_maps, "agent": conf["controller"], "seed": seed})
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
    """Each case's (and localization's, where the rows have one) mean and sample standard deviation over its seeds."""
    keys = [c for c in ("case", "localization") if c in rows.columns]
    out = []
    for names, group in rows.groupby(keys, sort=False):
        row: dict[str, Any] = {**dict(zip(keys, names)), "seed": f"{len(group)} seeds"}
        for column in rows.columns:
            if column in (*keys, "seed") or not np.issubdtype(group[column].dtype, np.number):
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
    parser.add_argument("--seeds", type=seed_list, default=[0, 1, 2])
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--train-workers", type=int, default=1, help="trainings at once (processes sharing the GPU)")
    parser.add_argument("--train-only", action="store_true", help="record and train, do not check")
    parser.add_argument("--teach-repeat", default="", metavar="LOCALIZATION,...",
                        help="teach each check route and repeat it with these localizations (ground_truth, place_loop, ...)")
    parser.add_argument("--retrieval", default=None, help="the place network of --teach-repeat's maps (a retrieval model.ckpt)")
    parser.add_argument("--route-length-m", default=None, metavar="MIN,MAX",
                        help="check routes of lengths drawn evenly in MIN-MAX m (default: the demonstrations' route length)")
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
    localizations = [n for n in args.teach_repeat.split(",") if n]
    if localizations:
        check_names([n for n in localizations if n != "ground_truth"], "--teach-repeat", PLACE_OBSERVATIONS)
        if not args.retrieval or not Path(args.retrieval).is_file():
            parser.error(f"--teach-repeat needs --retrieval, a retrieval model.ckpt (got {args.retrieval})")
    check_length_m = None
    if args.route_length_m:
        parts = args.route_length_m.split(",")
        try:
            low, high = float(parts[0]), float(parts[-1])
        except ValueError:
            parser.error(f"--route-length-m: MIN,MAX in metres (got {args.route_length_m!r})")
        if len(parts) > 2:
            parser.error(f"--route-length-m: MIN,MAX or one length (got {args.route_length_m!r})")
        if not 0 < low <= high:
            parser.error(f"--route-length-m: 0 < MIN <= MAX (got {args.route_length_m!r})")
        check_length_m = (low, high)
    seeds = args.seeds
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)

    models = {(case, seed): controller_path(case, train_maps, seed, conf, work) for case, train_maps, _ in cases
              for seed in seeds}
    spawn = multiprocessing.get_context("spawn")  # not forked: the trainings may have started CUDA in this process
    with ProcessPoolExecutor(args.workers, mp_context=spawn, initializer=_init_worker, initargs=(conf, maps, args.retrieval, check_length_m)) as pool:
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
        started = time.perf_counter()
        checked: dict[str, list[tuple[int, Any]]] = {}
        junctions: dict[str, list[dict[str, Any]]] = {}
        loc_error: dict[str, list[float]] = {}
        untaught: dict[str, int] = {}
        if localizations:
            tasks = [(f"{case}|{seed}", str(models[(case, seed)]), r, test, localizations)
                     for case, _, test in cases for seed in seeds for r in range(routes)]
            for key, r, result in pool.map(_teach_repeat, tasks):
                if result is None:
                    untaught[key] = untaught.get(key, 0) + 1
                for name, (row, rows, error) in (result or {}).items():
                    checked.setdefault(f"{key}|{name}", []).append((r, row))
                    junctions.setdefault(f"{key}|{name}", []).extend(rows)
                    loc_error.setdefault(f"{key}|{name}", []).append(error)
        else:
            tasks = [(f"{case}|{seed}", str(models[(case, seed)]), r, test)
                     for case, _, test in cases for seed in seeds for r in range(routes)]
            for key, r, row, rows in pool.map(_check, tasks):
                checked.setdefault(key, []).append((r, row))
                junctions.setdefault(key, []).extend(rows)
        log.info("checks: %d routes in %.0f s", len(tasks), time.perf_counter() - started)

    rows = []
    for case, _, test in cases:
        for seed in seeds:
            for name in localizations or [None]:
                key = f"{case}|{seed}" + (f"|{name}" if name else "")
                if key not in checked:  # every route's teach drive failed
                    continue
                metrics = check_metrics([row for _, row in sorted(checked[key])])
                extra = {"localization": name, "untaught": float(untaught.get(f"{case}|{seed}", 0)),
                         "mean loc error m": float(np.mean(loc_error[key]))} if name else {}
                rows.append({"case": case, "seed": seed, **extra,
                             "val steer MAE": trained[(case, seed)].get("best/val/steer_mae", float("nan")),
                             **{k.removeprefix("check/"): v for k, v in metrics.items() if k != "check/routes"},
                             **junction_columns(pd.DataFrame(junctions[key]))})
    table = pd.DataFrame(rows)
    counts = [c for c in table.columns if c.startswith("success_") or c in OUTCOMES]
    table[counts] = table[counts].fillna(0.0)  # a condition or failure a seed did not meet: none of it
    how = f", taught and repeated with {', '.join(localizations)}" if localizations else ""
    length = (f"{check_length_m[0]:.0f}-{check_length_m[1]:.0f} m" if check_length_m
              else f"{float(conf['drive']['demonstrations']['route_length_m']):.0f} m")
    text = (f"{args.agent}, {routes} check routes of {length} per case and seed{how}\n\n"
            + table.to_markdown(index=False, floatfmt=".2f")
            + "\n\n" + summary(table).to_markdown(index=False))
    with markdown_copy(args.out):
        print(text)
    junction_rows = pd.DataFrame([{"case": key.split("|")[0], "seed": int(key.split("|")[1]),
                                   **({"localization": key.split("|")[2]} if localizations else {}), **row}
                                  for key, rows in junctions.items() for row in rows])
    with atomic_path(Path(args.out).with_suffix(".junctions.csv")) as tmp:
        junction_rows.to_csv(tmp, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
