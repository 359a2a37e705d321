"""The metric filter and the oracle at city scale: Heidelberg (994 km) and Malta (1,857 km), simulated drives.

    PYTHONPATH=src python benchmarks/bench_city.py [--maps heidelberg,malta] [--levels low,medium]
        [--drives 3] [--start-every 250] [--seed 0] [--figure] [--live N] [--set localization.metric.KEY=VALUE ...]
        [--out results/bench_city] [--report]

Maps: ``../shared/data/maps/{heidelberg.osm.pbf, malta-2018.osm.pbf}`` (see their README). Per map and
noise level (:data:`topoloc.odometry.simulate.NOISE_LEVELS`: ``low`` and ``medium`` span real
odometry, KITTI 00's ORB-SLAM2 and our stereo VO), ``--drives`` random drives of 3-10 km. Every drive is
localized from a start every ``--start-every`` metres beside the oracle (evaluation from many starts,
:func:`topoloc.registry` ``metric`` ``run_starts``), and once live from its first frame, step by step, to
time one filter: CPU seconds per step while unsure (before the first answer with confidence >= 0.9) and
after, as a multiple of real time for a car at 10 m/s (one step of ``cell_m`` = 0.2 s). Prints per map
and level and overall the share of the oracle-resolved starts localized, the median ratio to the oracle,
the accuracy after, the speed, the CPU of the oracle and the peak memory (resident set) of the process
(the maps run one after the other in one process; the peak is after each map). ``--figure`` draws the
belief over the whole map at a few moments of each map's first drive (``belief_<map>.png``). Writes the
per-start table to ``--out``/starts.csv and the speed table to ``--out``/speed.csv after every drive, so that
a stopped run keeps the drives it finished (``--report`` prints the tables of such a run again).
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from bench_simulated import load_conf, targets

from topoloc.graph.build_graph import build_road_graph
from topoloc.localization.belief_plot import BeliefSnapshot, near_mass, plot_belief
from topoloc.localization.evaluation import DriveTruth, Judge, score_start, start_frames
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make

REPO = Path(__file__).resolve().parents[1]
MAPS = {"heidelberg": REPO.parent / "shared" / "data" / "maps" / "heidelberg.osm.pbf",
        "malta": REPO.parent / "shared" / "data" / "maps" / "malta-2018.osm.pbf"}
SPEED_MPS = 10.0
CONFIRM_M = 200.0  #: localization.evaluate.confirm_m of the default config


def peak_mb() -> float:
    """Peak resident memory of this process so far, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def live_run(localizer, road: RoadMap, conf: dict, odometry: Odometry, sure: float,
             moments: list[float] | None, truth: DriveTruth, steps_driven: np.ndarray) -> tuple[dict, list[BeliefSnapshot]]:
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
            bank = localizer.filter.coarse if localizer.filter.in_coarse[0] else localizer.filter.fine
            cell_xy, weight, _ = localizer.filter.belief(0)
            snaps.append(BeliefSnapshot(float(steps_driven[j]), bank.edge_marginals()[0], int(truth.edge[frame]),
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--maps", default="heidelberg,malta")
    parser.add_argument("--levels", default="low,medium")
    parser.add_argument("--drives", type=int, default=3, help="random drives of 3-10 km per map and level")
    parser.add_argument("--start-every", type=float, default=250.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--figure", action="store_true", help="draw the belief over the map (first drive of each map)")
    parser.add_argument("--set", nargs="*", default=[], dest="overrides", help="config overrides KEY=VALUE")
    parser.add_argument("--out", default="results/bench_city")
    parser.add_argument("--live", type=int, default=None, help="time the live filter on the first this many drives of "
                        "each map and level only (default: every drive)")
    parser.add_argument("--report", action="store_true", help="only print the tables of the run in --out")
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.report:
        report(pd.read_csv(out / "starts.csv"), pd.read_csv(out / "speed.csv"))
        return 0
    conf = load_conf(args.overrides)
    loc_conf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    ev = conf["localization"]["evaluate"]
    out.mkdir(parents=True, exist_ok=True)
    rows, speed = [], []
    for map_index, map_name in enumerate(args.maps.split(",")):
        if not MAPS.get(map_name, Path("/nonexistent")).is_file():
            raise SystemExit(f"{map_name}: no map at {MAPS.get(map_name)} (the city maps are in ../shared/data/maps)")
        began = time.perf_counter()
        graph, _ = build_road_graph(str(MAPS[map_name]), conf["graph"]["highway_classes"],
                                    float(conf["graph"]["virtual_node_spacing_m"]))
        road = RoadMap(graph, conf["localization"]["decode"]["u_turns"])
        localizer = make("metric")
        localizer.reset(road, loc_conf)
        model, coarse = localizer.filter.model, localizer.coarse_model
        oracle = Oracle(graph, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
        judge = Judge(graph, ev["node_tolerance_m"])
        print(f"{map_name}: {graph.num_edges} roads, {graph.edges.length_m.sum() / 1000:.0f} km, {model.num_cells} cells"
              f" ({coarse.num_cells if coarse else 0} coarse), set up in {time.perf_counter() - began:.1f} s,"
              f" peak {peak_mb():.0f} MB", file=sys.stderr, flush=True)
        oracle_cpu = 0.0
        for level_index, level in enumerate(args.levels.split(",")):
            rng = np.random.default_rng([args.seed, map_index, level_index])
            for drive_index in range(args.drives):
                length = float(np.exp(rng.uniform(np.log(3000.0), np.log(10000.0))))
                sim = simulate_pattern_drive(graph, length, NOISE_LEVELS[level], rng, "random")
                driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(sim.gt_xy, axis=0).T))])
                truth = DriveTruth(sim.edge, sim.gt_xy, driven)
                odometry = sim.odometry
                starts = start_frames(truth.driven, args.start_every)
                t0 = time.process_time()
                path = true_path(graph, truth.edge, truth.xy, truth.driven)
                limits = {s: oracle.count(path, int(s), float(ev["confirm_m"])).localized_m for s in starts}
                oracle_cpu += time.process_time() - t0
                drive = f"{map_name}/{level}/{drive_index:02d}"
                t0 = time.process_time()
                runs = localizer.run_starts(odometry, road, loc_conf, starts)
                starts_cpu = time.process_time() - t0
                for start, observations, track in runs:
                    m = score_start(judge, truth, start, observations.frame, track.state, track.confidence, track.xy,
                                    float(ev["confirm_m"]), float(ev["sure"]))
                    limit = limits[start]
                    ratio = (m["localized_m"] / limit if np.isfinite(m["localized_m"]) else np.inf) if np.isfinite(limit) else np.nan
                    rows.append({"map": map_name, "level": level, "drive": drive, "start": start,
                                 "start_m": float(truth.driven[start]), "localizer": "metric", **m, "oracle_m": limit,
                                 "ratio": ratio})
                if args.live is not None and drive_index >= args.live:
                    speed.append({"map": map_name, "level": level, "drive": drive, "length_m": sim.length_m,
                                  "starts": len(starts), "starts_cpu_s": starts_cpu, "peak_mb": peak_mb()})
                    write_rows(out, rows, speed)
                    print(f"{drive}: {sim.length_m:.0f} m, {len(starts)} starts in {starts_cpu:.1f} s CPU; peak {peak_mb():.0f} MB",
                          file=sys.stderr, flush=True)
                    continue
                steps_driven = driven[np.minimum(localizer.observe(odometry, road, loc_conf).frame, len(driven) - 1)]
                moments = [100.0, 300.0, 600.0, 1000.0, 2000.0, 1e12] if args.figure and level_index == 0 and drive_index == 0 else None
                live, snaps = live_run(localizer, road, loc_conf, odometry, float(ev["sure"]), moments, truth, steps_driven)
                if snaps:
                    plot_belief(graph, snaps, out / f"belief_{map_name}.png",
                                f"Metric filter on {map_name} ({graph.edges.length_m.sum() / 1000:.0f} km of road): "
                                f"where could I be now? (a {sim.length_m / 1000:.1f} km drive, {level} noise)")
                speed.append({"map": map_name, "level": level, "drive": drive, "length_m": sim.length_m,
                              "starts": len(starts), "starts_cpu_s": starts_cpu, **live, "peak_mb": peak_mb()})
                write_rows(out, rows, speed)
                print(f"{drive}: {sim.length_m:.0f} m, {len(starts)} starts in {starts_cpu:.1f} s CPU; live: sure after "
                      f"{live['sure_after_m']:.0f} m, unsure {live['unsure_x_realtime']:.1f}x real time, after "
                      f"{live['after_x_realtime']:.0f}x; peak {peak_mb():.0f} MB", file=sys.stderr, flush=True)
        speed.append({"map": map_name, "level": "oracle", "drive": "", "starts_cpu_s": oracle_cpu, "peak_mb": peak_mb()})
    write_rows(out, rows, speed)
    report(pd.DataFrame(rows), pd.DataFrame(speed))
    return 0


def write_rows(out: Path, rows: list[dict], speed: list[dict]) -> None:
    """The per-start and speed tables so far (rewritten whole after every drive: a stopped run keeps its drives)."""
    for name, table in (("starts.csv", rows), ("speed.csv", speed)):
        tmp = out / f".{name}.tmp"
        pd.DataFrame(table).to_csv(tmp, index=False)
        tmp.replace(out / name)


def confirmed(frame: pd.DataFrame, confirm_m: float = CONFIRM_M) -> pd.DataFrame:
    """The starts whose drive goes on for at least ``confirm_m`` after the oracle's limit (elsewhere the oracle
    is unique "to the end of the drive" over less than ``confirm_m``, and so is a localizer judged)."""
    return frame[frame.length_m - frame.oracle_m >= confirm_m]


def with_confirmed(group: pd.DataFrame) -> dict[str, float]:
    """:func:`targets`, plus the localized share and median ratio on the :func:`confirmed` starts."""
    t, c = targets(group), targets(confirmed(group))
    return {**t, "confirmed": c["resolved"], "localized_confirmed": c["localized_share"], "ratio_confirmed": c["median_ratio"]}


def report(frame: pd.DataFrame, speeds: pd.DataFrame) -> None:
    """Markdown tables: the targets per map and level and overall, then the speed and memory."""
    rows = [{"map": m, "level": lv, **with_confirmed(g)} for (m, lv), g in frame.groupby(["map", "level"], sort=False)]
    rows += [{"map": m, "level": "all", **with_confirmed(g)} for m, g in frame.groupby("map", sort=False)]
    rows.append({"map": "all", "level": "all", **with_confirmed(frame)})
    print("## Localization from many starts (metric filter)\n")
    print(pd.DataFrame(rows).drop(columns=["confident_wrong_all"]).to_markdown(index=False, floatfmt=".3f"))
    live_cols = ["sure_after_m", "unsure_cpu_per_step", "unsure_worst_100", "after_cpu_per_step", "unsure_x_realtime",
                 "after_x_realtime"]
    drives = speeds[speeds.level != "oracle"].reindex(columns=[*speeds.columns.drop(live_cols, errors="ignore"), *live_cols])
    print("\n## Speed (one filter from the first frame; x real time at 10 m/s) and memory\n")
    cols = ["drive", "length_m", "starts", "starts_cpu_s", "sure_after_m", "unsure_cpu_per_step", "unsure_worst_100",
            "unsure_x_realtime", "after_x_realtime", "peak_mb"]
    print(drives[cols].to_markdown(index=False, floatfmt=".3g"))
    print("\nOracle CPU (all starts of all drives): " + ", ".join(
        f"{r.map} {r.starts_cpu_s:.1f} s" for r in speeds[speeds.level == "oracle"].itertuples()))
    t = targets(frame)
    step_s = 0.2
    print("\n## Targets\n")
    print(f"- localizes >= 95 % of the oracle-resolved starts: {t['localized_share']:.3f}")
    print(f"- median ratio to the oracle <= 1.3: {t['median_ratio']:.3f}")
    c = targets(confirmed(frame))
    print(f"  on the {c['resolved']} oracle-resolved starts with >= {CONFIRM_M:.0f} m of drive after the oracle's limit: "
          f"{c['localized_share']:.3f} localized, median ratio {c['median_ratio']:.3f}")
    print(f"- right on >= 97 % of the later steps: {t['accuracy_after']:.3f}")
    if drives.unsure_cpu_per_step.notna().any():
        print(f"- >= 10x real time while unsure (mean over drives of the unsure steps; the slowest drive): "
              f"{step_s / drives.unsure_cpu_per_step.mean():.1f}x; {step_s / drives.unsure_cpu_per_step.max():.1f}x")
        print(f"- faster once localized: {step_s / drives.after_cpu_per_step.mean():.0f}x")
    else:
        print("- speed: no drive was timed live (--live 0)")
    print(f"- peak memory <= 4 GB: {speeds.peak_mb.max():.0f} MB")


if __name__ == "__main__":
    sys.exit(main())
