"""Where the metric filter loses the truth on a city drive: per start, the truth's probability step by step.

    PYTHONPATH=src python benchmarks/trace_truth.py [--map heidelberg] [--level low] [--drive 0] [--every 500]
        [--maxlen M] [--set localization.metric.KEY=VALUE ...]

The drive is the ``--drive``-th of ``bench_city.py`` for that map and level (same seeds). All starts run in
one :class:`~topoloc.localization.metric.city_filter.CityFilter` as in the evaluation; after every step each
start's probability of the true road (the roads of the frames within 8 of the step's), its phase (coarse or
full grid), its entries and its answer are recorded. Prints per start the oracle's limit, the distance to
localized, where it handed over, whether the truth's probability ever reached zero, and the figures at a few
distances; ``--set localization.metric.coarse_min_cells=100000000`` runs the dense filter instead.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from bench_city import MAPS
from bench_simulated import load_conf

from topoloc.graph.build_graph import build_road_graph
from topoloc.localization.evaluation import DriveTruth, Judge, score_start, start_frames
from topoloc.localization.metric.city_filter import CityFilter
from topoloc.localization.metric.odometry_steps import odometry_steps
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--map", default="heidelberg")
    p.add_argument("--level", default="low")
    p.add_argument("--drive", type=int, default=0)
    p.add_argument("--every", type=float, default=500.0)
    p.add_argument("--maxlen", type=float, default=1e9, help="cut the drive after this many metres")
    p.add_argument("--set", nargs="*", default=[], dest="overrides")
    a = p.parse_args(argv)
    conf = load_conf(a.overrides)
    loc_conf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    ev = conf["localization"]["evaluate"]
    t0 = time.perf_counter()
    graph, _ = build_road_graph(str(MAPS[a.map]), conf["graph"]["highway_classes"], float(conf["graph"]["virtual_node_spacing_m"]))
    road = RoadMap(graph, conf["localization"]["decode"]["u_turns"])
    loc = make("metric")
    loc.reset(road, loc_conf)
    print(f"set up in {time.perf_counter() - t0:.1f} s", flush=True)
    rng = np.random.default_rng([0, list(MAPS).index(a.map), ["low", "medium"].index(a.level)])
    for _ in range(a.drive + 1):  # the drives of bench_city.py, in its order
        length = float(np.exp(rng.uniform(np.log(3000.0), np.log(10000.0))))
        sim = simulate_pattern_drive(graph, length, NOISE_LEVELS[a.level], rng, "random")
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(sim.gt_xy, axis=0).T))])
    cut = int(np.searchsorted(driven, a.maxlen))
    truth = DriveTruth(sim.edge[:cut], sim.gt_xy[:cut], driven[:cut])
    odo = Odometry(sim.odometry.xy[:cut], sim.odometry.yaw[:cut])
    print(f"drive {truth.driven[-1]:.0f} m, noise {sim.noise}", flush=True)
    oracle = Oracle(graph, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
    judge = Judge(graph, ev["node_tolerance_m"])
    path = true_path(graph, truth.edge, truth.xy, truth.driven)
    starts = start_frames(truth.driven, a.every)
    steps = odometry_steps(odo.xy, odo.yaw, float(conf["localization"]["metric"]["cell_m"]))
    first = np.searchsorted(steps.frame, starts, side="right")
    bank = CityFilter(loc.filter.model, loc.coarse_model, filters=len(starts))
    n_f, n = len(starts), len(steps)
    true_mass, phase = np.full((n_f, n), np.nan), np.zeros((n_f, n), int)
    ans, conf_, entries = np.full((n_f, n), -1), np.zeros((n_f, n)), np.zeros((n_f, n), int)
    t0 = time.process_time()
    for j in range(n):
        fresh = np.flatnonzero(first == j)
        if len(fresh):
            bank.start(fresh)
        bank.update(int(steps.direction[j]), float(steps.yaw[j]))
        fr = min(int(steps.frame[j]), len(truth.edge) - 1)
        near = np.unique(truth.edge[max(0, fr - 8):fr + 8])
        fine = bank.fine.edge_marginals()
        coarse = bank.coarse.edge_marginals() if bank.coarse is not None else None
        count_f = np.bincount(bank.fine.group // bank.fine.classes, minlength=n_f)
        count_c = np.bincount(bank.coarse.group // bank.coarse.classes, minlength=n_f) if coarse is not None else None
        for b, est in enumerate(bank.answers()):
            if first[b] > j:
                continue
            inc = bool(bank.in_coarse[b])
            true_mass[b, j] = (coarse if inc else fine)[b, near].sum()
            phase[b, j], entries[b, j] = int(inc), (count_c if inc else count_f)[b]
            ans[b, j], conf_[b, j] = est.edge, est.confidence
    print(f"CPU {time.process_time() - t0:.1f} s", flush=True)
    step_m = truth.driven[np.minimum(steps.frame, len(truth.driven) - 1)]
    for b, s in enumerate(starts):
        limit = oracle.count(path, int(s), float(ev["confirm_m"])).localized_m
        js = np.arange(first[b], n)
        m = score_start(judge, truth, s, steps.frame[js], ans[b, js], conf_[b, js], None, float(ev["confirm_m"]), float(ev["sure"]))
        d = step_m[js] - truth.driven[s]
        dead = np.flatnonzero(true_mass[b, js] < 1e-12)
        hand = np.flatnonzero(np.diff(phase[b, js]) != 0)
        print(f"start {b} at {truth.driven[s]:.0f} m: oracle {limit:.0f}, localized {m['localized_m']:.0f}, "
              f"acc {m['accuracy_after']:.3f}, handoffs at {[round(d[h + 1]) for h in hand]} m, "
              f"truth at zero on {len(dead)} steps")
        for q in [50, 100, 150, 200, 300, 400, 600, 800]:
            k = int(np.searchsorted(d, q))
            if k < len(js):
                j = js[k]
                right = ans[b, j] in set(truth.edge[max(0, steps.frame[j] - 8):steps.frame[j] + 8])
                print(f"   {q:4d} m: {'coarse' if phase[b, j] else 'fine  '} entries {entries[b, j]:7d} "
                      f"truth {true_mass[b, j]:.3g} answer confidence {conf_[b, j]:.3f} right {right}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
