"""Command line: ``topoloc localize`` for use outside the workflow.

::

    topoloc localize --graph results/kitti00/graph/graph.graphml --poses poses.txt \\
        [--decoder metric] [--model results/kitti00/model/model.ckpt] [--gps gps.csv | --origin LAT,LON,HEADING] \\
        --out drive [--html drive.html]

runs one or more localizers (``--decoder``, comma-separated registry names: ``metric``, the default, needs no
model; ``hmm`` neither; ``raw``, ``strategy1``, ``strategy2`` need the trajectory model) on the drive and
writes ``drive.csv`` (per localizer and update: frame, metres driven, the answer's road, confidence, map
position in the graph's CRS and as lat/lon where the localizer gives one, the traced-back path, and the answer's
top places ``place<i>_state``, ``_prob``, ``_x``, ``_y``: ``localization.places``) and
``drive.geojson`` (the first localizer's run in WGS84: roads of its path, its positions, and the track
when georeferenced); with ``--html`` also the interactive viewer of the drive (:mod:`topoloc.viewer`: every
localizer's answers over a time slider, the metric filter's belief, the georeferenced track). It prints where the
vehicle is at the end and since when the answer is sure, and the top places at the end where there are several (a
drive two places explain equally names both). A
georeference (``--gps``, ``--origin``) is optional: it only checks that the drive lies on the map. The
model is a checkpoint path, an MLflow model URI (``runs:/<id>/model``) or the run id of a ``train_rnn``
stage. Bad input ends with one line: ``topoloc: <file or option>: <what is wrong>``.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyproj

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.localization.drive_on_map import check_explained, check_on_map, write_geojson
from topoloc.localization.roadmap import RoadMap
from topoloc.localizer import ROAD_OBSERVATIONS
from topoloc.motion.georef import fit_rigid, from_origin, grid_heading_deg, to_map
from topoloc.motion.poses import Odometry
from topoloc.motion.poses import planar_yaw, read_gps, read_poses
from topoloc.registry import check_names, make, registry
from topoloc.trajectory.model import load_model
from topoloc.viewer.drive_view import drive_data
from topoloc.viewer.page import write_viewer

log = logging.getLogger("topoloc")


def load_conf(path: str | None, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The pipeline config of ``path`` (or the schema defaults) with ``overrides``, validated: the slices a localizer
    (and the viewer) reads."""
    conf = load(path, overrides)
    return {k: conf[k] for k in ("localization", "segmentation", "encoding", "viewer")}


def _georeference(args: argparse.Namespace, track: np.ndarray, yaw0: float, crs: str):
    if args.gps:
        gps = read_gps(args.gps, len(track))
        return fit_rigid(track, to_map(crs, gps[:, 0], gps[:, 1]))
    if args.origin:
        try:
            lat, lon, heading = (float(v) for v in args.origin.split(","))
        except ValueError:
            raise InputError("--origin", f"expected LAT,LON,HEADING_DEG, got {args.origin!r}") from None
        return from_origin(to_map(crs, lat, lon), grid_heading_deg(crs, lat, lon, heading), track[0], yaw0)
    return None


def _names(args: argparse.Namespace) -> list[str]:
    names = [n.strip() for n in args.decoder.split(",") if n.strip()]
    if not names:
        raise InputError("--decoder", "name at least one localizer")
    try:
        return check_names(names, "--decoder", ROAD_OBSERVATIONS)
    except InputError as err:
        raise InputError("--decoder", err.message) from None


def localize(args: argparse.Namespace) -> dict[str, Any]:
    """The ``localize`` subcommand: returns a short summary (also printed)."""
    names = _names(args)
    conf = load_conf(args.config, {"localization": {"decode": {"k": args.k}}} if args.k is not None else None)
    graph = RoadGraph.load(args.graph)
    poses = read_poses(args.poses)
    if len(poses) < 2:
        raise InputError(args.poses, f"empty trajectory: {len(poses)} pose(s), a drive needs at least two")
    odometry = Odometry.from_poses(poses)
    geo = _georeference(args, odometry.xy, float(planar_yaw(poses)[0]), graph.crs)
    track_xy = geo.apply(odometry.xy) if geo is not None else None
    if track_xy is not None:
        check_on_map(graph, track_xy, float(conf["localization"]["max_offmap_m"]), args.poses, args.graph)
    known = registry(ROAD_OBSERVATIONS)
    needs_model = [n for n in names if known[n].requires_model]
    if needs_model and args.model is None:
        raise InputError("--model", f"{', '.join(needs_model)} needs a trained model (a checkpoint, runs:/ID/model or a run id)")
    model = load_model(args.model, args.tracking_uri) if needs_model else None
    road = RoadMap(graph, conf["localization"]["decode"]["u_turns"], conf["localization"]["decode"]["max_skip_m"], model)
    to_lonlat = pyproj.Transformer.from_crs(graph.crs, "EPSG:4326", always_xy=True)
    loc_conf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    tables, seconds = [], {}
    for name in names:
        localizer = make(name)
        observations = localizer.observe(odometry, road, loc_conf)
        if len(observations) == 0:
            raise InputError(args.poses, f"empty trajectory: the drive covers {odometry.driven_m[-1]:.1f} m, too little for "
                                         f"any observation of {name} (one virtual-node spacing is "
                                         f"{graph.virtual_node_spacing_m:g} m)")
        began = time.process_time()
        localizer.reset(road, loc_conf)
        track = localizer.run(observations.items)
        seconds[name] = time.process_time() - began
        if geo is None and hasattr(localizer, "explained"):  # without a georeference: does the map explain the turns?
            check_explained(*localizer.explained(observations.items), float(conf["localization"]["min_explained_turns"]), args.poses)
        lon, lat = to_lonlat.transform(track.xy[:, 0], track.xy[:, 1])
        tables.append(pd.DataFrame({"localizer": name, "step": np.arange(len(track)), "frame": observations.frame,
                                    "driven_m": odometry.driven_m[observations.frame], "edge": track.state,
                                    "confidence": np.round(track.confidence, 5), "x": track.xy[:, 0], "y": track.xy[:, 1],
                                    "lat": lat, "lon": lon, "path": track.path,
                                    **track.place_columns(int(conf["localization"]["places"]["top"]))}))
    table = pd.concat(tables, ignore_index=True)
    out = Path(args.out)
    csv_path, geojson_path = out.with_name(out.name + ".csv"), out.with_name(out.name + ".geojson")
    with atomic_path(csv_path) as tmp:
        table.to_csv(tmp, index=False, float_format="%.7g")
    first = table[table.localizer == names[0]]
    write_geojson(geojson_path, graph, first, names[0], track_xy)
    if args.html:
        answers = table.rename(columns={"edge": "state"})
        data = drive_data(f"topoloc localize: {Path(args.poses).name}", graph, odometry, answers, conf, track_xy, road=road)
        write_viewer(args.html, graph, data, conf["viewer"]["tiles"])
    final = first.iloc[-1]
    sure = first.confidence.to_numpy() >= (args.sure if args.sure is not None else conf["localization"]["evaluate"]["sure"])
    places = []
    rank = 1
    while f"place{rank}_state" in first.columns and int(final[f"place{rank}_state"]) >= 0:
        plon, plat = to_lonlat.transform(float(final[f"place{rank}_x"]), float(final[f"place{rank}_y"]))
        places.append({"edge": int(final[f"place{rank}_state"]), "probability": float(final[f"place{rank}_prob"]),
                       "lat": float(plat), "lon": float(plon)})
        rank += 1
    unsure = np.flatnonzero(~sure)
    since = None if not sure[-1] else float(first.driven_m.iloc[unsure[-1] + 1 if len(unsure) else 0])
    return {"localizer": names[0], "label": known[names[0]].label, "updates": len(first), "edge_now": int(final.edge),
            "name_now": str(graph.edges["name"].iat[int(final.edge)]) if final.edge >= 0 else "",
            "confidence_now": float(final.confidence), "lat": float(final.lat), "lon": float(final.lon),
            "sure_since_m": since, "places_now": places, "seconds": {k: round(v, 4) for k, v in seconds.items()},
            "csv": str(csv_path), "geojson": str(geojson_path), "html": args.html}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="topoloc", description="Map-based geolocalization from motion.")
    sub = parser.add_subparsers(dest="command", required=True)
    loc = sub.add_parser("localize", help="localize a drive (KITTI poses) on a road graph: CSV and GeoJSON",
                         description="Localize a drive on a road graph from its odometry.")
    loc.add_argument("--graph", required=True, help="road graph GraphML of the build_graph stage")
    loc.add_argument("--poses", required=True, help="KITTI poses file: one 3x4 camera-to-world matrix per line (any frame)")
    loc.add_argument("--decoder", "--localizer", default="metric",
                     help="localizer(s), comma-separated: metric (default), hmm, raw, strategy1, strategy2")
    loc.add_argument("--model", help="trajectory model for raw / strategy1 / strategy2: checkpoint (.ckpt), MLflow model URI "
                                     "(runs:/<id>/model) or train_rnn run id")
    geo = loc.add_mutually_exclusive_group()
    geo.add_argument("--gps", help="optional georeference: per-frame GPS CSV frame,lat,lon[,alt]")
    geo.add_argument("--origin", help="optional georeference: LAT,LON,HEADING_DEG of frame 0 (heading clockwise from north)")
    loc.add_argument("--out", required=True, help="output prefix: writes PREFIX.csv and PREFIX.geojson")
    loc.add_argument("--html", help="also write the interactive viewer of the drive to this HTML file (offline, self-contained)")
    loc.add_argument("--k", type=int, default=None, help="hypotheses kept per step by Strategy 1 / 2 (default: localization.decode.k)")
    loc.add_argument("--config", help="pipeline config YAML (its segmentation / encoding / localization keys are used)")
    loc.add_argument("--tracking-uri", help="MLflow store for run ids (default: MLFLOW_TRACKING_URI or results/mlflow.db)")
    loc.add_argument("--sure", type=float, default=None,
                     help="confidence from which the answer counts as sure (summary only; default: localization.evaluate.sure)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``topoloc`` command."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("mlflow").setLevel(logging.WARNING)
    try:
        if args.command == "localize":
            s = localize(args)
            where = (f"road {s['edge_now']}" + (f" ({s['name_now']})" if s["name_now"] and s["name_now"] != "nan" else "")
                     + (f" at {s['lat']:.6f}, {s['lon']:.6f}" if np.isfinite(s["lat"]) else ""))
            sure = f"sure since {s['sure_since_m']:.0f} m" if s["sure_since_m"] is not None else "not sure yet"
            print(f"topoloc localize: {s['label']}, {s['updates']} updates: {where}, confidence {s['confidence_now']:.2f}, "
                  f"{sure}; wrote {s['csv']}, {s['geojson']}" + (f" and {s['html']}" if s["html"] else ""))
            if len(s["places_now"]) > 1:  # where else it may be: the top places, most probable first
                print("top places now: " + "; ".join(
                    f"{i}. road {p['edge']} ({p['probability']:.2f})" + (f" at {p['lat']:.6f}, {p['lon']:.6f}" if np.isfinite(p["lat"]) else "")
                    for i, p in enumerate(s["places_now"], 1)))
    except InputError as err:
        print(f"topoloc: {err}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
