"""Experiment ``city``: the metric filter and the oracle at city scale (Heidelberg 994 km, Malta 1,857 km of road) on
simulated drives, one job per noise level (rule ``localize_city``), and their summary (rule ``summarize_city``).

Per map and level, ``drives`` random drives of 3-10 km drawn from ``[seed, map's place, level's place]``. Every drive
is localized from a start every ``start_every_m`` (``starts_per_bank`` at a time) beside the oracle, and once live
from its first frame, step by step, to time one filter: CPU seconds per step while unsure (before the first answer
with confidence >= ``sure``) and after, as a multiple of real time for a car at 10 m/s (one step of ``cell_m`` =
0.2 s). The peak memory (resident set) is the job's process after each drive; the maps run one after the other in it.
"""

from __future__ import annotations

import json
import logging
import resource
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.experiments.many_starts import confirmed, start_rows, targets, with_confirmed
from topoloc.experiments.summary import write_summary
from topoloc.graph.from_osm import build_road_graph
from topoloc.io import atomic_path, write_json, write_text
from topoloc.localization.belief_plot import BeliefSnapshot, near_mass, plot_belief
from topoloc.localization.evaluation import DriveTruth, Judge, start_frames
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.localizers.metric import MetricLocalizer
from topoloc.motion.poses import Odometry
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make

log = logging.getLogger(__name__)

SPEED_MPS = 10.0
FIGURES = ["localized_share", "median_ratio", "accuracy_after", "localized_confirmed", "ratio_confirmed",
           "unsure_x_realtime", "after_x_realtime", "peak_mb"]


def peak_mb() -> float:
    """Peak resident memory of this process so far, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def live_run(localizer: MetricLocalizer, road: RoadMap, conf: dict[str, Any], odometry: Odometry, sure: float,
             moments: list[float] | None, truth: DriveTruth,
             steps_driven: np.ndarray) -> tuple[dict[str, float], list[BeliefSnapshot]]:
    """One filter from the first frame, step by step: CPU per step while unsure and after; belief snapshots."""
    observations = localizer.observe(odometry, road, conf)
    localizer.reset(road, conf)
    localizer.start()
    cpu, confidence, snaps = [], [], []
    wanted = list(moments or [])
    for j, item in enumerate(observations.items):
        began = time.process_time()
        answer = localizer.update(item)
        cpu.append(time.process_time() - began)
        confidence.append(answer.confidence)
        if wanted and (steps_driven[j] >= wanted[0] or j == len(observations.items) - 1):
            wanted.pop(0)
            frame = int(observations.frame[j])
            cell_xy, weight, _ = localizer.filter.belief(0)
            snaps.append(BeliefSnapshot(float(steps_driven[j]), localizer.filter.road_marginals(0), int(truth.edge[frame]),
                                        truth.xy[frame], truth.xy[:frame + 1], near_mass(cell_xy, weight, truth.xy[frame])))
    cpu, confidence = np.asarray(cpu), np.asarray(confidence)
    first = int(np.argmax(confidence >= sure)) if (confidence >= sure).any() else len(cpu)
    step_s = float(conf["localization"]["metric"]["cell_m"]) / SPEED_MPS
    unsure, after = cpu[:first], cpu[first:]
    return {"steps": len(cpu), "sure_after_m": float(steps_driven[first]) if first < len(cpu) else np.nan,
            "unsure_cpu_per_step": float(unsure.mean()) if len(unsure) else np.nan,
            "unsure_worst_100": float(np.convolve(unsure, np.ones(100) / 100, "valid").max()) if len(unsure) >= 100 else np.nan,
            "after_cpu_per_step": float(after.mean()) if len(after) else np.nan,
            "unsure_x_realtime": step_s / float(unsure.mean()) if len(unsure) else np.nan,
            "after_x_realtime": step_s / float(after.mean()) if len(after) else np.nan,
            "live_cpu_s": float(cpu.sum())}, snaps


def localize_level(conf: dict[str, Any], level: str, figures: Path | None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Every city map's drives at one noise ``level``: the per-start table and the speed table (one row per drive,
    then one ``oracle`` row per map). ``figures``: the folder of the belief figures, or None for none."""
    exp = conf["city"]
    loc_conf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    ev = conf["localization"]["evaluate"]
    level_index = list(exp["levels"]).index(level)
    live = exp["live_drives"]
    rows, speed = [], []
    for map_index, map_name in enumerate(exp["maps"]):
        osm = exp["osm"].get(map_name)
        if osm is None or not Path(osm).is_file():
            raise InputError(f"experiments.city.osm.{map_name}", f"no OSM file at {osm}")
        began = time.perf_counter()
        graph, _ = build_road_graph(str(osm), conf["graph"]["highway_classes"], float(conf["graph"]["virtual_node_spacing_m"]))
        road = RoadMap(graph, conf["localization"]["decode"]["u_turns"])
        localizer = make("metric")
        localizer.reset(road, loc_conf)
        model, coarse = localizer.filter.model, localizer.coarse_model
        oracle = Oracle(graph, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
        judge = Judge(graph, ev["node_tolerance_m"])
        log.info("%s: %d roads, %.0f km, %d cells (%d coarse), set up in %.1f s, peak %.0f MB", map_name, graph.num_edges,
                 graph.edges.length_m.sum() / 1000, model.num_cells, coarse.num_cells if coarse else 0,
                 time.perf_counter() - began, peak_mb())
        oracle_cpu = 0.0
        rng = np.random.default_rng([int(exp["seed"]), map_index, level_index])
        for drive_index in range(int(exp["drives"])):
            length = float(np.exp(rng.uniform(np.log(3000.0), np.log(10000.0))))
            sim = simulate_pattern_drive(graph, length, NOISE_LEVELS[level], rng, "random")
            driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(sim.gt_xy, axis=0).T))])
            truth = DriveTruth(sim.edge, sim.gt_xy, driven)
            odometry = sim.odometry
            starts = start_frames(truth.driven, float(exp["start_every_m"]))
            t0 = time.process_time()
            path = true_path(graph, truth.edge, truth.xy, truth.driven)
            limits = {s: oracle.count(path, int(s), float(ev["confirm_m"])).localized_m for s in starts}
            oracle_cpu += time.process_time() - t0
            drive = f"{map_name}/{level}/{drive_index:02d}"
            t0 = time.process_time()
            bank = int(exp["starts_per_bank"])  # a bank's broad beliefs take memory (each start with its challenger)
            runs = [run for k in range(0, len(starts), bank)
                    for run in localizer.run_starts(odometry, road, loc_conf, starts[k:k + bank])]
            starts_cpu = time.process_time() - t0
            rows += start_rows(judge, truth, runs, limits, ev, "metric", map=map_name, level=level, drive=drive)
            row = {"map": map_name, "level": level, "drive": drive, "length_m": sim.length_m, "starts": len(starts),
                   "starts_cpu_s": starts_cpu}
            if live is not None and drive_index >= int(live):
                speed.append({**row, "peak_mb": peak_mb()})
                continue
            steps_driven = driven[np.minimum(localizer.observe(odometry, road, loc_conf).frame, len(driven) - 1)]
            draw = figures is not None and level_index == 0 and drive_index == 0
            moments = [100.0, 300.0, 600.0, 1000.0, 2000.0, 1e12] if draw else None
            measured, snaps = live_run(localizer, road, loc_conf, odometry, float(ev["sure"]), moments, truth, steps_driven)
            if snaps:
                plot_belief(graph, snaps, figures / f"belief_{map_name}.png",
                            f"Metric filter on {map_name} ({graph.edges.length_m.sum() / 1000:.0f} km of road): "
                            f"where could I be now? (a {sim.length_m / 1000:.1f} km drive, {level} noise)")
            speed.append({**row, **measured, "peak_mb": peak_mb()})
            log.info("%s: %.0f m, %d starts in %.1f s CPU; live: sure after %.0f m, unsure %.1fx real time; peak %.0f MB",
                     drive, sim.length_m, len(starts), starts_cpu, measured["sure_after_m"],
                     measured["unsure_x_realtime"], peak_mb())
        speed.append({"map": map_name, "level": "oracle", "drive": "", "starts_cpu_s": oracle_cpu, "peak_mb": peak_mb()})
    return pd.DataFrame(rows), pd.DataFrame(speed)


LIVE_COLUMNS = ["sure_after_m", "unsure_cpu_per_step", "unsure_worst_100", "after_cpu_per_step", "unsure_x_realtime",
                "after_x_realtime"]


def report(frame: pd.DataFrame, speeds: pd.DataFrame, confirm_m: float, step_s: float) -> str:
    """Markdown: the targets per map and level and overall, then the speed and memory."""
    rows = [{"map": m, "level": lv, **with_confirmed(g, confirm_m)} for (m, lv), g in frame.groupby(["map", "level"], sort=False)]
    rows += [{"map": m, "level": "all", **with_confirmed(g, confirm_m)} for m, g in frame.groupby("map", sort=False)]
    rows.append({"map": "all", "level": "all", **with_confirmed(frame, confirm_m)})
    out = ["## Localization from many starts (metric filter)\n",
           pd.DataFrame(rows).drop(columns=["confident_wrong_all"]).to_markdown(index=False, floatfmt=".3f")]
    drives = speeds[speeds.level != "oracle"].reindex(columns=[*speeds.columns.drop(LIVE_COLUMNS, errors="ignore"), *LIVE_COLUMNS])
    cols = ["drive", "length_m", "starts", "starts_cpu_s", "sure_after_m", "unsure_cpu_per_step", "unsure_worst_100",
            "unsure_x_realtime", "after_x_realtime", "peak_mb"]
    out += ["\n## Speed (one filter from the first frame; x real time at 10 m/s) and memory\n",
            drives[cols].to_markdown(index=False, floatfmt=".3g"),
            "\nOracle CPU (all starts of all drives): " + ", ".join(
                f"{r.map} {r.starts_cpu_s:.1f} s" for r in speeds[speeds.level == "oracle"].itertuples())]
    t, c = targets(frame), targets(confirmed(frame, confirm_m))
    out += ["\n## Targets\n",
            f"- localizes >= 95 % of the oracle-resolved starts: {t['localized_share']:.3f}",
            f"- median ratio to the oracle <= 1.3: {t['median_ratio']:.3f}",
            f"  on the {c['resolved']} oracle-resolved starts with >= {confirm_m:.0f} m of drive after the oracle's limit: "
            f"{c['localized_share']:.3f} localized, median ratio {c['median_ratio']:.3f}",
            f"- right on >= 97 % of the later steps: {t['accuracy_after']:.3f}"]
    if drives.unsure_cpu_per_step.notna().any():
        out += [f"- >= 10x real time while unsure (mean over drives of the unsure steps; the slowest drive): "
                f"{step_s / drives.unsure_cpu_per_step.mean():.1f}x; {step_s / drives.unsure_cpu_per_step.max():.1f}x",
                f"- faster once localized: {step_s / drives.after_cpu_per_step.mean():.0f}x"]
    else:
        out.append("- speed: no drive was timed live (experiments.city.live_drives: 0)")
    out.append(f"- peak memory <= 4 GB: {speeds.peak_mb.max():.0f} MB")
    return "\n".join(out) + "\n"


def level_figures(frame: pd.DataFrame, speeds: pd.DataFrame, confirm_m: float, step_s: float) -> dict[str, float]:
    """The figures of one level's job: the targets, on the confirmed starts too, the live speed, the peak memory."""
    figures = with_confirmed(frame, confirm_m)
    drives = speeds[speeds.level != "oracle"]
    timed = drives.get("unsure_cpu_per_step", pd.Series(dtype=float)).dropna()
    figures["unsure_x_realtime"] = step_s / float(timed.mean()) if len(timed) else np.nan
    after = drives.get("after_cpu_per_step", pd.Series(dtype=float)).dropna()
    figures["after_x_realtime"] = step_s / float(after.mean()) if len(after) else np.nan
    figures["peak_mb"] = float(speeds.peak_mb.max())
    return {k: float(v) for k, v in figures.items()}


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """One noise level (``conf['level']``): ``starts`` and ``speed`` (CSV), ``figures`` (markdown), ``metrics`` (JSON)."""
    starts = Path(outputs["starts"])
    starts.parent.mkdir(parents=True, exist_ok=True)
    frame, speeds = localize_level(conf, str(conf["level"]), starts.parent if conf["city"]["figure"] else None)
    confirm_m = float(conf["localization"]["evaluate"]["confirm_m"])
    step_s = float(conf["localization"]["metric"]["cell_m"]) / SPEED_MPS
    for key, table in (("starts", frame), ("speed", speeds)):
        with atomic_path(outputs[key]) as tmp:
            table.to_csv(tmp, index=False)
    write_text(outputs["figures"], report(frame, speeds, confirm_m, step_s))
    metrics = {k: v for k, v in level_figures(frame, speeds, confirm_m, step_s).items() if np.isfinite(v)}
    write_json(outputs["metrics"], metrics)
    return metrics


def summarize(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """``summary`` (markdown) and ``json``: per level the job's figures (inputs ``metrics_<level>``), and their mean
    and spread over the levels."""
    exp = conf["city"]
    jobs = pd.DataFrame([{"level": level, **{f: np.nan for f in FIGURES},
                          **json.loads(Path(inputs[f"metrics_{level}"]).read_text())} for level in exp["levels"]])
    sentence = (f"The metric filter beside the oracle on {', '.join(exp['maps'])}: per map and noise level "
                f"{exp['drives']} random drives of 3-10 km (seed {exp['seed']}), a start every "
                f"{exp['start_every_m']:g} m, and the live filter timed from the first frame (x real time at 10 m/s); "
                f"per level the figures of the oracle-resolved starts (confirmed: with at least confirm_m of drive "
                f"after the oracle's limit), then their mean and sample standard deviation over the levels.")
    write_summary(outputs, "City-scale maps: the metric filter against the oracle", sentence, jobs, "level", [], FIGURES)
    return {f"{f}_mean": float(jobs[f].mean()) for f in FIGURES if jobs[f].notna().any()}
