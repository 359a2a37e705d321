"""Stage ``segment_trajectory``: turns and distances of an odometry track, as tokens with edge labels.

The georeferenced odometry track (``frames.csv`` of ``extract_odometry``) is
simplified with Douglas-Peucker (``segmentation.tolerance_m``); its corners cut
the track into segments. Each segment's length is the odometry's path length
between its corners, its start/end headings the direction of travel over
``encoding.heading_lookahead_m`` (shared with the training paths) after its first / before its last corner,
leaving out ``segmentation.corner_skip_m`` next to each corner, where a vehicle is still rounding it
(:func:`topoloc.segmentation.track_end_headings`). The segments go through
:func:`topoloc.encoding.encode_segments`, the same function as the training
routes, so train and test tokens share one convention (:func:`topoloc.segmentation.encode_track`).

Each token's ground-truth edge is the frame label at the token's place: for a
virtual node, the frame ``k * spacing`` along its segment; for a turn, the
frame ``turn_label_offset_m`` past the corner (the road taken after the turn).
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.geometry import straight_token
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json
from topoloc.odometry.plot import plot_segments
from topoloc.segmentation import encode_track

log = logging.getLogger(__name__)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Segment the drive in ``inputs['frames']`` and write tokens, segments, stats and the Fig. 9(a)-style figure."""
    seg_conf, bins = conf["segmentation"], int(conf["encoding"]["angle_bins"])
    if bins < 4:
        raise InputError("encoding.angle_bins", f"must be at least 4, got {bins}")
    graph = RoadGraph.load(inputs["graph"])
    spacing = graph.virtual_node_spacing_m
    try:
        frames = pd.read_csv(inputs["frames"])
        xy = frames[["x", "y"]].to_numpy(float)
        edge = frames["edge_id"].to_numpy(np.int64)
    except (KeyError, ValueError, pd.errors.ParserError) as err:
        raise InputError(inputs["frames"], f"not a frames table of extract_odometry ({err})") from err
    if len(xy) < 2:
        raise InputError(inputs["frames"], "a drive needs at least two frames")
    started = time.perf_counter()
    track = encode_track(xy, spacing, bins, float(seg_conf["tolerance_m"]), float(conf["encoding"]["heading_lookahead_m"]),
                         float(seg_conf["turn_label_offset_m"]), float(seg_conf["corner_skip_m"]))
    elapsed = time.perf_counter() - started
    seg, encoded, kind, frame_of = track.segments, track.encoded, track.kind, track.frame
    corners = seg["corners"]
    straight = straight_token(bins)
    tokens = pd.DataFrame({"index": np.arange(len(encoded.tokens)), "token": encoded.tokens, "segment": encoded.segment,
                           "kind": kind, "frame": frame_of, "distance_m": track.place_m, "edge_id": edge[frame_of],
                           "x": xy[frame_of, 0], "y": xy[frame_of, 1]})
    segments = pd.DataFrame({"segment": np.arange(len(corners) - 1), "start_frame": corners[:-1], "end_frame": corners[1:],
                             "length_m": seg["lengths"], "heading_start_deg": seg["heading_start"],
                             "heading_end_deg": seg["heading_end"], "start_edge_id": edge[corners[:-1]]})
    stats = {"frames": len(xy), "corners": len(corners), "segments": len(corners) - 1, "tokens": len(encoded.tokens),
             "turn_tokens": int(sum(k == "turn" for k in kind)),
             "non_straight_turns": int(sum(k == "turn" and tok != straight for k, tok in zip(kind, encoded.tokens))),
             "distinct_edges": int(tokens.edge_id.nunique()), "segmentation_s": elapsed,
             "tolerance_m": float(seg_conf["tolerance_m"]), "angle_bins": bins, "virtual_node_spacing_m": spacing}
    log.info("%d frames -> %d segments, %d tokens in %.3f s", len(xy), stats["segments"], stats["tokens"], elapsed)
    plot_segments(xy, corners, outputs["figure"],
                  f"{conf.get('drive', '')}: {stats['segments']} segments (DP {seg_conf['tolerance_m']} m), {stats['tokens']} tokens")
    for name, table in (("tokens", tokens), ("segments", segments)):
        with atomic_path(outputs[name]) as tmp:
            table.to_csv(tmp, index=False, float_format="%.3f")
    write_json(outputs["stats"], stats)
    return {k: float(v) for k, v in stats.items() if isinstance(v, int | float)}
