"""Command line: ``topoloc localize`` for use outside the workflow.

::

    topoloc localize --model results/kitti00/model/model.ckpt --graph results/kitti00/graph/graph.graphml \\
        --poses poses.txt [--gps gps.csv | --origin LAT,LON,HEADING] --out drive

segments the poses into tokens (as the ``segment_trajectory`` stage), runs the
RNN and the decoders, and writes ``drive.csv`` (per token: every decoder's
online answer, decoded edge and confidence) and ``drive.geojson`` (the chosen
decoder's edge sequence in WGS84, and the track when georeferenced). The
model is a checkpoint path, an MLflow model URI (``runs:/<id>/model``) or the
run id of a ``train_rnn`` stage. Bad input ends with one line:
``topoloc: <file or option>: <what is wrong>``.
"""

from __future__ import annotations

import argparse
import copy
import logging
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError

log = logging.getLogger("topoloc")

#: Defaults of the config keys the CLI uses (the schema's defaults; ``--config`` overrides them).
DEFAULTS: dict[str, Any] = {
    "segmentation": {"tolerance_m": 5.0, "corner_skip_m": 10.0, "turn_label_offset_m": 5.0},
    "encoding": {"heading_lookahead_m": 10.0},
    "localization": {
        "rnn": {"window": 60, "stride": 20},
        "decode": {"k": 5, "initial_hypotheses": "all", "score": "joint", "reseed": 5, "reseed_penalty": 5.0,
                   "u_turns": "dead_ends", "max_skip_m": None},
        "hmm": {"enabled": True, "cell_m": 5.0, "angle_sigma_deg": 20.0, "distance_sigma_m": 2.5,
                "straight_virtual_prob": 0.85, "floor": 0.01, "reset_prob": 0.0001, "heading_window_m": 10.0},
        "evaluate": {"confirm_m": 200.0, "initial_hypotheses": 5},
        "max_offmap_m": 30.0,
        "min_explained_turns": 0.5,
    },
}


def _merge(base: dict[str, Any], override: dict[str, Any], where: str = "") -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in override.items():
        if key not in out:
            continue  # other pipeline keys (region, graph, ...) are not used here
        if isinstance(out[key], dict):
            if not isinstance(value, dict):
                raise InputError(f"{where}{key}", "expected a mapping")
            out[key] = _merge(out[key], value, f"{where}{key}.")
        else:
            out[key] = value
    return out


def load_conf(path: str | None) -> dict[str, Any]:
    """:data:`DEFAULTS`, overridden by the matching keys of a pipeline config file."""
    if path is None:
        return copy.deepcopy(DEFAULTS)
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text()) or {}
    except OSError as err:
        raise InputError(path, f"cannot read the config file ({err.strerror})") from err
    except yaml.YAMLError as err:
        raise InputError(path, f"not a YAML file ({str(err).splitlines()[0]})") from err
    if not isinstance(data, dict):
        raise InputError(path, "a config file is a YAML mapping")
    return _merge(DEFAULTS, data)


def _georeference(args: argparse.Namespace, track: np.ndarray, yaw0: float, crs: str):
    from topoloc.odometry.georef import fit_rigid, from_origin, grid_heading_deg, to_map
    from topoloc.odometry.poses import read_gps

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


def localize(args: argparse.Namespace) -> dict[str, Any]:
    """The ``localize`` subcommand: returns a short summary (also printed)."""
    from topoloc.graph.road_graph import RoadGraph
    from topoloc.localization.localize import (Localizer, check_explained, check_on_map, decoded_table, write_geojson,
                                               write_table)
    from topoloc.localization.rnn import load_model
    from topoloc.odometry.poses import planar_track, planar_yaw, read_poses
    from topoloc.odometry.segment_trajectory import encode_track

    conf = load_conf(args.config)
    if args.k is not None:
        conf["localization"]["decode"]["k"] = args.k
    graph = RoadGraph.load(args.graph)
    poses = read_poses(args.poses)
    if len(poses) < 2:
        raise InputError(args.poses, f"empty trajectory: {len(poses)} pose(s), a drive needs at least two")
    track = planar_track(poses)
    geo = _georeference(args, track, float(planar_yaw(poses)[0]), graph.crs)
    xy = geo.apply(track) if geo is not None else track
    if geo is not None:
        check_on_map(graph, xy, float(conf["localization"]["max_offmap_m"]), args.poses, args.graph)
    model = load_model(args.model, args.tracking_uri)
    seg = conf["segmentation"]
    track_tokens = encode_track(xy, graph.virtual_node_spacing_m, int(model.hparams.bins), float(seg["tolerance_m"]),
                                float(conf["encoding"]["heading_lookahead_m"]), float(seg["turn_label_offset_m"]),
                                float(seg["corner_skip_m"]))
    tokens = track_tokens.encoded.tokens
    if len(tokens) == 0:
        raise InputError(args.poses, f"empty trajectory: the drive covers {track_tokens.segments['cum'][-1]:.1f} m, "
                                     f"less than one virtual-node spacing ({graph.virtual_node_spacing_m:g} m)")
    decoders = ("raw", "strategy1", "strategy2") + (("hmm",) if conf["localization"]["hmm"]["enabled"] and not args.no_hmm else ())
    if args.decoder not in decoders:
        raise InputError("--decoder", f"{args.decoder!r} is not run; choose from {list(decoders)}")
    localizer = Localizer(model, graph, conf["localization"], hmm="hmm" in decoders)
    result = localizer.localize(tokens, decoders)
    if geo is None:
        check_explained(result, float(conf["localization"]["min_explained_turns"]), args.poses)
    frame = pd.DataFrame({"index": np.arange(len(tokens)), "token": tokens, "kind": track_tokens.kind,
                          "frame": track_tokens.frame, "distance_m": track_tokens.place_m})
    if geo is not None:
        frame["x"], frame["y"] = xy[track_tokens.frame, 0], xy[track_tokens.frame, 1]
    table = decoded_table(frame, result)
    out = Path(args.out)
    csv_path, geojson_path = out.with_name(out.name + ".csv"), out.with_name(out.name + ".geojson")
    write_table(csv_path, table)
    write_geojson(geojson_path, graph, table, args.decoder, xy if geo is not None else None)
    final = result.decoded[args.decoder]
    sure = final.confidence >= args.sure
    unsure = np.flatnonzero(~sure)
    since = None if not sure[-1] else float(track_tokens.place_m[unsure[-1] + 1 if len(unsure) else 0])
    summary = {"tokens": len(tokens), "decoder": args.decoder, "edge_now": int(final.online[-1]),
               "confidence_now": float(final.confidence[-1]), "sure_since_m": since,
               "seconds": {k: round(v, 4) for k, v in result.seconds.items()}, "csv": str(csv_path), "geojson": str(geojson_path)}
    return summary


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="topoloc", description="Map-based geolocalization from motion.")
    sub = parser.add_subparsers(dest="command", required=True)
    loc = sub.add_parser("localize", help="decode a drive (KITTI poses) into a road-edge sequence: CSV and GeoJSON",
                         description="Localize a drive on a road graph with a trained trajectory RNN and multi-hypothesis decoding.")
    loc.add_argument("--model", required=True, help="model checkpoint (.ckpt), MLflow model URI (runs:/<id>/model) or train_rnn run id")
    loc.add_argument("--graph", required=True, help="road graph GraphML of the build_graph stage (the map the model was trained on)")
    loc.add_argument("--poses", required=True, help="KITTI poses file: one 3x4 camera-to-world matrix per line")
    geo = loc.add_mutually_exclusive_group()
    geo.add_argument("--gps", help="optional georeference: per-frame GPS CSV frame,lat,lon[,alt]")
    geo.add_argument("--origin", help="optional georeference: LAT,LON,HEADING_DEG of frame 0 (heading clockwise from north)")
    loc.add_argument("--out", required=True, help="output prefix: writes PREFIX.csv and PREFIX.geojson")
    loc.add_argument("--decoder", default="strategy1", help="decoder of the GeoJSON and the summary (raw, strategy1, strategy2, hmm)")
    loc.add_argument("--k", type=int, default=None, help="hypotheses kept per step (default: localization.decode.k)")
    loc.add_argument("--config", help="pipeline config YAML whose segmentation / encoding / localization keys override the defaults")
    loc.add_argument("--tracking-uri", help="MLflow store for run ids (default: MLFLOW_TRACKING_URI or results/mlflow.db)")
    loc.add_argument("--no-hmm", action="store_true", help="skip the HMM baseline")
    loc.add_argument("--sure", type=float, default=0.9, help="confidence above which the answer counts as sure (summary only)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``topoloc`` command."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("mlflow").setLevel(logging.WARNING)
    try:
        if args.command == "localize":
            summary = localize(args)
            print(f"topoloc localize: {summary['tokens']} tokens; {summary['decoder']}: edge {summary['edge_now']} now "
                  f"(confidence {summary['confidence_now']:.2f}), sure since "
                  + (f"{summary['sure_since_m']:.0f} m" if summary["sure_since_m"] is not None else "never")
                  + f"; wrote {summary['csv']} and {summary['geojson']}")
    except InputError as err:
        print(f"topoloc: {err}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
