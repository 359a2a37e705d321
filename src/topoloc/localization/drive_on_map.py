"""A drive on the map: checks that a drive belongs to the map (used by the ``topoloc localize`` CLI) and the
GeoJSON of a localizer's answers on the map (the CLI and the ``decode_trajectories`` stage)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path


def offmap_distance(graph: RoadGraph, xy: NDArray[np.float64]) -> float:
    """Median distance of (up to 500 of) the points ``xy`` to the nearest road, in metres."""
    import shapely

    tree = shapely.STRtree([shapely.LineString(g) for g in graph.geometry])
    points = shapely.points(np.asarray(xy, float)[:: max(1, len(xy) // 500)])
    _, dist = tree.query_nearest(points, return_distance=True, all_matches=False)
    return float(np.median(dist))


def check_on_map(graph: RoadGraph, xy: NDArray[np.float64], max_offmap_m: float, where: str, graph_name: str = "the map") -> None:
    """InputError when a georeferenced drive lies away from the roads (a drive for a different map)."""
    offmap = offmap_distance(graph, xy)
    if offmap > max_offmap_m:
        raise InputError(where, f"the georeferenced track lies {offmap:.0f} m (median) from the roads of {graph_name}: "
                                "nothing matches; a drive for a different map?")


def check_explained(share: float, turns: int, min_share: float, where: str, min_turns: int = 8) -> None:
    """InputError when the HMM's best path explains too few of the drive's turns (heuristic, without a georeference)."""
    if turns >= min_turns and np.isfinite(share) and share < min_share:
        raise InputError(where, f"nothing matches: the map turns where the drive does at only {share:.0%} of its {turns} turns "
                                f"(localization.min_explained_turns {min_share:.0%}); a drive for a different map?")


def _to_lonlat(graph: RoadGraph):
    import pyproj

    transformer = pyproj.Transformer.from_crs(graph.crs, "EPSG:4326", always_xy=True)
    return lambda xy: np.column_stack(transformer.transform(np.asarray(xy)[:, 0], np.asarray(xy)[:, 1]))


def runs_of(edges: NDArray[np.int64]) -> list[tuple[int, int, int]]:
    """Maximal runs of one edge in a sequence: ``(edge, first_step, last_step)``."""
    edges = np.asarray(edges)
    if len(edges) == 0:
        return []
    cuts = np.flatnonzero(np.diff(edges) != 0) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts - 1, [len(edges) - 1]])
    return [(int(edges[a]), int(a), int(b)) for a, b in zip(starts, ends)]


def place_features(graph: RoadGraph, answers: pd.DataFrame, localizer: str, to_lonlat) -> list[dict]:
    """Points of the top places of the last answer of ``answers`` (its ``place<i>_*`` columns), most probable first."""
    if len(answers) == 0:
        return []
    last = answers.iloc[-1]
    out = []
    rank = 1
    while f"place{rank}_state" in answers.columns:
        edge, prob = int(last[f"place{rank}_state"]), float(last[f"place{rank}_prob"])
        x, y = float(last[f"place{rank}_x"]), float(last[f"place{rank}_y"])
        if edge >= 0 and np.isfinite([x, y]).all():
            out.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": np.round(to_lonlat([[x, y]])[0], 7).tolist()},
                        "properties": {"kind": "place", "localizer": localizer, "rank": rank, "edge_id": edge,
                                       "probability": round(prob, 4), "frame": int(last["frame"]),
                                       "name": str(graph.edges["name"].iat[edge])}})
        rank += 1
    return out


def write_geojson(path: str | Path, graph: RoadGraph, answers: pd.DataFrame, localizer: str,
                  track_xy: NDArray[np.float64] | None = None) -> None:
    """GeoJSON (WGS84) of one localizer's run: one LineString per run of one road along its traced-back
    ``path`` (with its steps, frames and mean confidence), the answers' positions where it has them, the top
    places of the last answer (one Point each, ``kind`` ``place``: rank, road, probability; the first is the
    answer) and the track if given. ``answers`` holds that run's rows (columns ``path``, ``confidence``,
    ``frame``, and optionally ``x``, ``y`` and the place columns ``place<i>_state``, ``_prob``, ``_x``, ``_y``)."""
    to_lonlat = _to_lonlat(graph)
    features = []
    path_edges = answers["path"].to_numpy(np.int64)
    frames = answers["frame"].to_numpy(np.int64)
    confidence = answers["confidence"].to_numpy(float)
    for order, (edge, first, last) in enumerate(runs_of(path_edges)):
        if edge < 0:
            continue
        row = graph.edges.iloc[edge]
        features.append({
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": np.round(to_lonlat(graph.geometry[edge]), 7).tolist()},
            "properties": {"kind": "decoded_edge", "localizer": localizer, "order": order, "edge_id": edge,
                           "first_step": first, "last_step": last, "first_frame": int(frames[first]),
                           "last_frame": int(frames[last]), "name": str(row["name"]), "highway": str(row.highway),
                           "mean_confidence": round(float(confidence[first:last + 1].mean()), 4)},
        })
    if {"x", "y"} <= set(answers.columns) and answers[["x", "y"]].notna().all(axis=1).any():
        known = answers[answers[["x", "y"]].notna().all(axis=1)]
        lonlat = np.round(to_lonlat(known[["x", "y"]].to_numpy(float)), 7)
        features.append({"type": "Feature", "properties": {"kind": "positions", "localizer": localizer,
                                                           "frames": known["frame"].astype(int).tolist(),
                                                           "confidence": np.round(known["confidence"], 4).tolist()},
                         "geometry": {"type": "MultiPoint", "coordinates": lonlat.tolist()}})
    features += place_features(graph, answers, localizer, to_lonlat)
    if track_xy is not None and len(track_xy) > 1:
        step = max(1, len(track_xy) // 2000)
        features.append({"type": "Feature", "properties": {"kind": "track"},
                         "geometry": {"type": "LineString", "coordinates": np.round(to_lonlat(track_xy[::step]), 7).tolist()}})
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps({"type": "FeatureCollection", "features": features}) + "\n")
