"""Stage ``extract_odometry``: a drive's odometry, georeferenced, evaluated and labelled with road edges.

Sources (``odometry.source``):

* ``simulated``: random drives on the map with a noise model (:mod:`topoloc.odometry.simulate`);
* ``kitti_poses``: a KITTI poses file (ground truth or any SLAM output), optional timestamps; with a drive's
  ``noise`` the poses' motion is corrupted by the odometry noise model (:func:`topoloc.motion.noise.noisy_poses`,
  seeded): the ground truth made a stereo-VO-like odometry;
* ``kitti_stereo``: our stereo visual odometry on a KITTI sequence folder (:mod:`topoloc.odometry.stereo_vo`);
* ``rendered``: the same stereo VO on a drive rendered from the map by the ``render_drive`` stage
  (:mod:`topoloc.render.render_drive`; drive names from :mod:`topoloc.render.conditions`): its sequence
  folder is the folder of ``inputs['calib']``, with
  ground truth, timestamps and per-frame GPS beside it; ``inputs['truth']`` (``route.csv``) adds the true
  road edge of every frame.

Outputs: ``poses`` (estimate, KITTI format, local frame), ``frames`` (per-frame
diagnostics: map position of estimate and ground truth, edge label, distance to
it, flag), ``stats`` (JSON), ``figure`` (top view on the map) and
``evaluation`` (estimate versus ground truth).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json
from topoloc.motion.georef import Georeference, fit_rigid, from_origin, grid_heading_deg, to_map
from topoloc.motion.noise import OdometryNoise, noisy_poses
from topoloc.motion.poses import (
    planar_track,
    planar_yaw,
    poses_from_planar,
    read_gps,
    read_poses,
    read_times,
    write_poses,
)
from topoloc.odometry.drives import SOURCES, simulated_drive_names
from topoloc.odometry.evaluate import align_rigid, evaluate
from topoloc.odometry.mapmatch import match_track
from topoloc.odometry.plot import plot_evaluation, plot_track
from topoloc.odometry.simulate import simulate_drive
from topoloc.odometry.stereo_vo import run_stereo_vo

log = logging.getLogger(__name__)


def check_on_map(graph: RoadGraph, xy: np.ndarray, max_offmap_m: float, drive: str, where: str) -> None:
    """InputError naming ``where`` (the gps file or ``odometry.origin``) when the track ``xy`` lies off the map.

    Off the map means: the median distance of its positions (at most 1000, evenly spaced) to the nearest
    road exceeds ``max_offmap_m`` (a drive of another city, a wrong origin).
    """
    import shapely

    tree = shapely.STRtree([shapely.LineString(g) for g in graph.geometry])
    sample = np.asarray(xy, float)[:: max(1, len(xy) // 1000)]
    _, dist = tree.query_nearest(shapely.points(sample), return_distance=True, all_matches=False)
    median = float(np.median(dist))
    if median > max_offmap_m:
        far = f"{median / 1000:,.0f} km" if median >= 10_000 else f"{median:,.0f} m"
        raise InputError(where, f"drive {drive} lies {far} (median) from the roads of the map ({np.mean(dist <= 5.0):.0%} "
                                f"of its frames within 5 m; odometry.max_offmap_m {max_offmap_m:g}): the drive is not in this region")


def _georeference(track: np.ndarray, yaw0: float, gps_xy: np.ndarray | None, conf: dict[str, Any], crs: str) -> Georeference:
    if gps_xy is not None:
        return fit_rigid(track, gps_xy)
    origin = conf["origin"]
    if not origin:
        raise InputError("odometry.origin", "a drive without a gps file needs odometry.origin {lat, lon, heading_deg}")
    xy0 = to_map(crs, origin["lat"], origin["lon"])
    heading = grid_heading_deg(crs, origin["lat"], origin["lon"], origin["heading_deg"])
    return from_origin(xy0, heading, track[0], yaw0)


def _load_kitti(conf: dict[str, Any], drive: str, inputs: dict[str, str]) -> dict[str, Any]:
    """Poses (from a file or our stereo VO), optional ground truth, times, GPS of a KITTI-style drive."""
    extra: dict[str, Any] = {}
    if conf["source"] == "kitti_poses":
        est = read_poses(inputs["poses"])
        flagged = np.zeros(len(est), dtype=bool)
        files = conf["drives"].get(drive) or {}  # the stage's inputs name the files; the drive's config adds noise
        noise, seed = files.get("noise"), int(files.get("noise_seed", 0))
        if noise:  # a noisy odometry made from the poses (e.g. the ground truth at a stereo-VO level), seeded
            est = noisy_poses(est, OdometryNoise.from_dict(noise), np.random.default_rng(seed))
            extra["noise"] = {**noise, "seed": seed}
    else:
        sequence = conf["drives"][drive]["sequence"] if conf["source"] == "kitti_stereo" else Path(inputs["calib"]).parent
        est, flagged, extra = run_stereo_vo(sequence, conf["stereo"])
    gt = read_poses(inputs["ground_truth"]) if "ground_truth" in inputs else None
    if gt is not None and len(gt) != len(est):
        raise InputError(inputs["ground_truth"], f"{len(gt)} ground-truth poses for {len(est)} estimated poses")
    times = read_times(inputs["times"], len(est)) if "times" in inputs else None
    gps = read_gps(inputs["gps"], len(est)) if "gps" in inputs else None
    return {"est": est, "gt": gt, "times": times, "gps": gps, "flagged": flagged, "extra": extra}


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Produce the odometry of drive ``conf['drive']`` and its per-frame edge labels on ``inputs['graph']``."""
    source = conf["source"]
    drive = conf["drive"]
    if source not in SOURCES:
        raise InputError("odometry.source", f"unknown source {source!r}; choose from {list(SOURCES)}")
    graph = RoadGraph.load(inputs["graph"])
    true_edges = None
    extra: dict[str, Any] = {}
    if source == "simulated":
        sim = conf["simulated"]
        index = simulated_drive_names(conf).index(drive)
        rng = np.random.default_rng([int(sim["seed"]), index])
        drv = simulate_drive(graph, float(sim["length_m"]), float(sim["frame_spacing_m"]), sim["noise"], rng)
        # Local KITTI frame: frame 0 at the origin, optical axis (+z, yaw 90 deg in (x, z)) along the start heading.
        geo = Georeference(float(drv.gt_yaw[0] - np.pi / 2.0), drv.gt_xy[0].copy())
        to_local = lambda xy: (xy - geo.t) @ geo.rotation  # noqa: E731 (inverse of geo.apply)
        est_map = drv.gt_xy[0] + drv.odometry.xy  # the odometry starts at the true start pose
        est = poses_from_planar(to_local(est_map), drv.odometry.yaw - geo.theta)
        gt = poses_from_planar(to_local(drv.gt_xy), drv.gt_yaw - geo.theta)
        times = np.arange(len(est)) * float(sim["frame_spacing_m"]) / float(sim["speed_mps"])
        gt_map = drv.gt_xy
        flagged = np.zeros(len(est), dtype=bool)
        true_edges = drv.edge
        georef = {"method": "simulation start pose", **geo.to_dict(np.pi / 2.0)}
        label_source = "ground truth"
    else:
        data = _load_kitti(conf, drive, inputs)
        est, gt, times, flagged, extra = data["est"], data["gt"], data["times"], data["flagged"], data["extra"]
        gps_xy = to_map(graph.crs, data["gps"][:, 0], data["gps"][:, 1]) if data["gps"] is not None else None
        geo_est = _georeference(planar_track(est), float(planar_yaw(est)[0]), gps_xy, conf, graph.crs)
        est_map = geo_est.apply(planar_track(est))
        georef = {"method": "rigid fit to GPS" if gps_xy is not None else "origin", **geo_est.to_dict(float(planar_yaw(est)[0]))}
        if gt is not None:
            geo_gt = _georeference(planar_track(gt), float(planar_yaw(gt)[0]), gps_xy, conf, graph.crs)
            gt_map = geo_gt.apply(planar_track(gt))
            georef["ground_truth"] = geo_gt.to_dict(float(planar_yaw(gt)[0]))
            label_source = "ground truth"
        elif gps_xy is not None:
            gt_map, label_source = None, "GPS"
        else:
            gt_map, label_source = None, "odometry (no ground truth or GPS)"
            log.warning("drive %s: no ground truth or GPS; labels come from the odometry itself", drive)
        if times is None:
            times = np.arange(len(est)) / float(conf["frame_rate_hz"])
        if "truth" in inputs:
            true_edges = pd.read_csv(inputs["truth"])["edge_id"].to_numpy()
            if len(true_edges) != len(est):
                raise InputError(inputs["truth"], f"{len(true_edges)} frames for {len(est)} estimated poses")
    label_xy = gt_map if gt_map is not None else (gps_xy if source != "simulated" and gps_xy is not None else est_map)
    if source != "simulated":
        check_on_map(graph, label_xy, float(conf["max_offmap_m"]), drive, inputs["gps"] if gps_xy is not None else "odometry.origin")
    mm = conf["map_matching"]
    match = match_track(graph, label_xy, radius_m=mm["radius_m"], sigma_m=mm["sigma_m"])

    stats: dict[str, Any] = {"source": source, "drive": drive, "frames": len(est), "georeference": georef,
                             "label_source": label_source, "flagged_frames": int(flagged.sum()), **extra}
    stats["length_m"] = float(np.hypot(*np.diff(est_map, axis=0).T).sum())
    stats["labels"] = {
        "distinct_edges": int(len(np.unique(match.edge_id))),
        "unconnected_changes": match.jumps,
        "within_5m": float(np.mean(match.distance_m <= 5.0)),
        "median_distance_m": float(np.median(match.distance_m)),
    }
    if true_edges is not None:
        stats["labels"]["agreement_with_simulation"] = float(np.mean(true_edges == match.edge_id))
    aligned = None
    if gt is not None:
        stats["evaluation"] = evaluate(gt, est)
        aligned = align_rigid(planar_track(est), planar_track(gt))
    frames = pd.DataFrame({
        "frame": np.arange(len(est)), "time_s": times, "x": est_map[:, 0], "y": est_map[:, 1],
        "gt_x": gt_map[:, 0] if gt_map is not None else np.nan, "gt_y": gt_map[:, 1] if gt_map is not None else np.nan,
        "edge_id": match.edge_id, "edge_distance_m": match.distance_m, "flagged": flagged.astype(int),
    })
    if true_edges is not None:
        frames["true_edge_id"] = true_edges
    log.info("drive %s (%s): %d frames, %.0f m, %d edges, %.1f%% of label points within 5 m",
             drive, source, len(est), stats["length_m"], stats["labels"]["distinct_edges"], 100 * stats["labels"]["within_5m"])
    title = f"{drive} ({source}): {len(est)} frames, {stats['length_m']:.0f} m"
    plot_track(graph, est_map, gt_map, match.edge_id, outputs["figure"], title)
    ev = stats.get("evaluation")
    ev_title = (f"{drive}: t_err {ev['t_err_pct']:.2f} %, r_err {ev['r_err_deg_per_100m']:.3f} deg/100 m, ATE {ev['ate_m']:.2f} m"
                if ev else f"{drive}: no ground truth")
    plot_evaluation(planar_track(gt) if gt is not None else None, aligned, outputs["evaluation"], ev_title)
    write_poses(outputs["poses"], est)
    with atomic_path(outputs["frames"]) as tmp:
        frames.to_csv(tmp, index=False, float_format="%.3f")
    write_json(outputs["stats"], stats)
    metrics = {"frames": len(est), "length_m": stats["length_m"], "flagged_frames": stats["flagged_frames"], **extra,
               **{f"labels_{k}": v for k, v in stats["labels"].items()},
               **{k: v for k, v in (ev or {}).items() if np.isfinite(v)}}
    return {k: float(v) for k, v in metrics.items() if isinstance(v, int | float)}
