"""Benchmark of the metric filter where the map explains the drive badly: confident wrong answers and recovery.

The ablation table in docs/localization.md ("The metric filter on maps with errors") comes from it;
``bench_map_errors`` (on :mod:`topoloc.odometry.map_errors`) is the benchmark of the map-error types. Drives are
simulated on the true map (random walks of 1.5-2.5 km, medium odometry noise) and localized on a perturbed copy that keeps the road ids: nodes moved
(``node`` m sd per axis, the geometry follows), inner vertices moved (``vertex``), Douglas-Peucker at
``simplify`` m, ``phantom`` x roads of straight two-way links that do not exist; and each drive leaves the map once
for a 120 m loop (a parking lot: 30 m out to the right, 60 m back, onto the road again, then driven on;
:func:`topoloc.odometry.map_error_drives.off_map_loop`). ``--level`` (``LEVELS``): ``medium`` all of it, ``low`` less,
``detour`` the loop alone, ``node`` the nodes moved alone, ``geom`` nodes, vertices and simplification without the
loop or phantom roads, ``none`` the exact map. A neighbouring road counts right near the true junction
(:class:`topoloc.localization.evaluation.Judge` with the true nodes), not near the moved node.

    python -m benchmarks.bench_filter_recovery [--graph results/helsinki/graph/graph.graphml] [--level medium]
        [--drives 2] [--seeds 1,2] [--start-every 300] [--set localization.metric.heading_sigma_deg=8 ...]

Prints one JSON line of figures: starts, resolved (by the oracle of the perturbed map; starts up to 200 m before
the loop end are scored before it only), loc_share and median_ratio (of the resolved starts), cw (confident
wrong: confidence >= 0.9 and wrong, of all answers; off the map every road is wrong), recov_* (from the return
onto the map: localized again within 1.5x the oracle's distance from there, the median ratio, never, and
``recov_within_1.5_fresh``: within 1.5x the distance a filter started fresh at the return takes, the best a
recovery can do on that map), ece (the expected calibration error of all answers, "no road" right off the map),
and the CPU seconds of the filter; then the recoveries of the start at frame 0 of
each drive (``fresh_m``: the fresh start's distance, inf where it never localizes).
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.markdown import add_out_option, markdown_copy, seed_list
from topoloc.config import dotted_overrides, load
from topoloc.graph.road_graph import RoadGraph
from topoloc.localization import calibration
from topoloc.localization.evaluation import Judge, localized_step, start_frames
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.noise import OdometryNoise, integrate_odometry
from topoloc.odometry.map_error_drives import off_map_loop
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.registry import make
from topoloc.segmentation import douglas_peucker

REPO = Path(__file__).resolve().parents[1]

LEVELS = {"none": dict(node=0.0, vertex=0.0, simplify=0.0, phantom=0.0, detour=0.0),
          "low": dict(node=1.5, vertex=0.5, simplify=1.0, phantom=0.03, detour=1.0),
          "detour": dict(node=0.0, vertex=0.0, simplify=0.0, phantom=0.0, detour=1.0),
          "node": dict(node=2.5, vertex=0.0, simplify=0.0, phantom=0.0, detour=0.0),
          "geom": dict(node=2.5, vertex=1.0, simplify=3.0, phantom=0.0, detour=0.0),
          "medium": dict(node=2.5, vertex=1.0, simplify=3.0, phantom=0.08, detour=1.0)}


def perturb(graph: RoadGraph, rng: np.random.Generator, node: float, vertex: float, simplify: float,
            phantom: float) -> RoadGraph:
    """The map a localizer sees: nodes moved (sd ``node`` m), inner vertices (``vertex``), simplified, phantom roads."""
    g = copy.deepcopy(graph)
    nodes = g.nodes.copy()
    disp = {n: rng.normal(0, node, 2) for n in nodes.index}
    nodes["x"] = nodes.x + np.array([disp[n][0] for n in nodes.index])
    nodes["y"] = nodes.y + np.array([disp[n][1] for n in nodes.index])
    geom, lengths = [], []
    for e, pts in enumerate(g.geometry):
        u, v = int(g.edges.u.iat[e]), int(g.edges.v.iat[e])
        seg = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        f = seg / max(seg[-1], 1e-9)
        p = pts + (1 - f)[:, None] * disp[u] + f[:, None] * disp[v]
        if len(p) > 2:
            p[1:-1] += rng.normal(0, vertex, (len(p) - 2, 2))
            if simplify > 0:
                p = p[douglas_peucker(p, simplify)]  # the project's own, not GEOS's (whose output varies by version)
        geom.append(p)
        lengths.append(float(np.hypot(*np.diff(p, axis=0).T).sum()))
    edges = g.edges.copy()
    edges["length_m"] = lengths
    if phantom > 0:  # roads that do not exist: straight two-way links between nodes 40-150 m apart
        xy = nodes[["x", "y"]].to_numpy(float)
        ids = nodes.index.to_numpy()
        linked = set(zip(edges.u, edges.v)) | set(zip(edges.v, edges.u))
        want = int(round(phantom * len(edges)))
        new = []
        for _ in range(50 * want):
            if len(new) >= want:
                break
            a, b = rng.choice(len(ids), 2, replace=False)
            d = float(np.hypot(*(xy[a] - xy[b])))
            if 40 <= d <= 150 and (ids[a], ids[b]) not in linked:
                linked |= {(ids[a], ids[b]), (ids[b], ids[a])}
                new.append((a, b, d))
        rows = []
        for a, b, d in new:
            r = edges.iloc[0].copy()
            r["u"], r["v"], r["length_m"], r["oneway"] = ids[a], ids[b], d, 0
            rows.append(r)
            geom.append(np.array([xy[a], xy[b]]))
        if rows:
            edges = pd.concat([edges, pd.DataFrame(rows)], ignore_index=True)
            edges.index.name = "edge_id"
    g2 = RoadGraph(nodes, edges, geom, g.crs, g.virtual_node_spacing_m)
    deg = pd.Series(0, index=nodes.index)
    for u, v in zip(edges.u, edges.v):
        deg[u] += 1
        deg[v] += 1
    g2.nodes["degree"] = deg
    return g2


def run(conf: dict, graph: RoadGraph, level: str, n_drives: int, seed: int, start_every: float = 300.0,
        localizer: str = "metric", detour: bool = True, length: tuple[float, float] = (1500, 2500)
        ) -> tuple[pd.DataFrame, pd.DataFrame, float]:
    """One seed's drives at one map-error level: the per-start table, the recoveries after the loop, the CPU."""
    ev = conf["localization"]["evaluate"]
    lconf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    rng = np.random.default_rng(seed)
    err = LEVELS[level]
    mapg = perturb(graph, rng, err["node"], err["vertex"], err["simplify"], err["phantom"]) if err["node"] + err["phantom"] > 0 else graph
    road = RoadMap(mapg, conf["localization"]["decode"]["u_turns"])
    oracle = Oracle(mapg, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
    judge = Judge(mapg, ev["node_tolerance_m"], graph.nodes)  # near a node: near the true junction, not the moved one
    loc = make(localizer)
    loc.reset(road, lconf)
    rows, recov, cpu = [], [], 0.0
    for d in range(n_drives):
        L = float(rng.uniform(*length))
        sim = simulate_pattern_drive(graph, L, NOISE_LEVELS["medium"], rng, "random")
        xy, yaw, edge = sim.gt_xy, sim.gt_yaw, sim.edge
        rejoin = None
        if detour and err["detour"] > 0 and sim.length_m > 1200:
            xy, yaw, edge, rejoin = off_map_loop(xy, yaw, edge, float(rng.uniform(0.35, 0.55)) * sim.length_m)
        odo = integrate_odometry(xy, yaw, OdometryNoise.from_dict(sim.noise), rng)
        driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        starts = start_frames(driven, start_every)
        extra = [] if rejoin is None or rejoin in set(starts.tolist()) else [rejoin]  # a fresh start at the return
        t0 = time.process_time()
        runs = loc.run_starts(odo, road, lconf, np.sort(np.concatenate([starts, np.asarray(extra, starts.dtype)])))
        cpu += time.process_time() - t0
        on = edge >= 0
        # the oracle on the on-map part after the detour (or the whole drive)
        first_on = rejoin if rejoin is not None else 0
        sub = np.arange(first_on, len(edge))
        path = true_path(mapg, edge[sub], xy[sub], driven[sub] - driven[first_on])
        limits = {}
        for s in starts:
            if s >= first_on:
                limits[s] = oracle.count(path, int(s - first_on), ev["confirm_m"]).localized_m
            elif rejoin is not None:
                limits[s] = np.nan  # starts before the detour: scored on their stretch before it
        rej_oracle = oracle.count(path, 0, ev["confirm_m"]).localized_m if rejoin is not None else np.nan
        fresh_m, first_recovery = np.nan, len(recov)
        for s, obs, track in runs:
            fr = np.asarray(obs.frame)
            st = np.asarray(track.state)
            conf_ = np.asarray(track.confidence)
            m = on[fr]
            judged = judge.right(st, edge[fr], xy[fr])  # off the map "no road" is right (calibration) ...
            right = judged & m  # ... but localized and confident wrong count on-map answers only
            dist = driven[fr] - driven[s]
            if s == rejoin:  # the fresh start at the return
                step = localized_step(right, dist, ev["confirm_m"])
                fresh_m = dist[step] if step is not None else np.inf
            if s in extra:
                continue
            cw = ~right & (conf_ >= ev["sure"])
            row = {"drive": d, "start": s, "steps": len(fr), "cw": cw.sum(), "cw_off": (cw & ~m).sum(),
                   **calibration.bin_sums(conf_, judged)}
            if rejoin is not None and s >= rejoin - 200 and s < rejoin:
                continue
            if rejoin is None or s >= rejoin:
                step = localized_step(right, dist, ev["confirm_m"])
                row["loc"] = dist[step] if step is not None else np.nan
                row["oracle"] = limits.get(s, np.nan)
            else:
                # before the detour: localized before it, and found again after it
                stp = localized_step(right[fr < rejoin], dist[fr < rejoin], ev["confirm_m"])
                row["loc"] = dist[stp] if stp is not None else np.nan
                row["oracle"] = np.nan
                post = fr >= rejoin
                if post.any() and s < rejoin - 400:
                    ps = localized_step(right[post], driven[fr[post]] - driven[rejoin], ev["confirm_m"])
                    recov.append({"drive": d, "start": s, "recover_m": driven[fr[post]][ps] - driven[rejoin] if ps is not None else np.nan,
                                  "oracle_m": rej_oracle, "left_m": driven[-1] - driven[rejoin],
                                  "cw_after": int(cw[post].sum()), "steps_after": int(post.sum())})
            rows.append(row)
        for r in recov[first_recovery:]:  # the fresh start at the return comes after the starts that recover
            r["fresh_m"] = fresh_m
    return pd.DataFrame(rows), pd.DataFrame(recov), cpu


def summary(tab: pd.DataFrame, rec: pd.DataFrame, cpu: float) -> dict[str, float]:
    """The figures of one setting: localized share and median ratio of the resolved starts, confident wrong, recovery."""
    res = tab[np.isfinite(tab.oracle)]
    out = {"starts": len(tab), "resolved": len(res), "loc_share": float(np.isfinite(res["loc"]).mean()) if len(res) else np.nan,
           "median_ratio": float(np.median(np.where(np.isfinite(res["loc"]), res["loc"], np.inf) / res.oracle)) if len(res) else np.nan,
           "cw": float(tab.cw.sum() / tab.steps.sum()), "cw_offmap": float(tab.cw_off.sum() / tab.steps.sum()),
           "ece": calibration.ece(tab), "cpu": cpu}
    if len(rec):
        r = rec[np.isfinite(rec.oracle_m)]
        ratio = np.where(np.isfinite(r.recover_m), r.recover_m, np.inf) / r.oracle_m
        out.update({"recov_n": len(r), "recov_within_1.5": float(np.mean(ratio <= 1.5)), "recov_median_ratio": float(np.median(ratio)) if len(r) else np.nan,
                    "recov_never": float(np.mean(~np.isfinite(r.recover_m))),
                    "recov_within_1.5_fresh": float(np.mean(np.where(np.isfinite(r.recover_m), r.recover_m, np.inf)
                                                            <= 1.5 * r.fresh_m)), "cw_after_detour": float(rec.cw_after.sum() / max(rec.steps_after.sum(), 1))})
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graph", default="results/helsinki/graph/graph.graphml", help="the true road graph")
    parser.add_argument("--level", default="medium", choices=list(LEVELS))
    parser.add_argument("--drives", type=int, default=2, help="drives per seed")
    parser.add_argument("--seeds", type=seed_list, default=[1, 2])
    parser.add_argument("--start-every", type=float, default=300.0)
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="override config keys")
    parser.add_argument("--configfile", default=str(REPO / "config" / "config.yaml"))
    add_out_option(parser, "bench_filter_recovery")
    args = parser.parse_args(argv)
    with markdown_copy(args.out):
        conf = load(args.configfile, dotted_overrides(args.set))
        graph = RoadGraph.load(args.graph)
        parts = [run(conf, graph, args.level, args.drives, int(s), args.start_every) for s in args.seeds]
        tab = pd.concat([p[0] for p in parts])
        rec = pd.concat([p[1] for p in parts])
        figures = summary(tab, rec, sum(p[2] for p in parts))
        print(f"## The metric filter on a perturbed map, level {args.level}, {' '.join(args.set) or 'defaults'}\n")
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in figures.items()}) + "\n")
        if len(rec):
            print(rec[rec.start == 0].to_markdown(index=False, floatfmt=".1f"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
