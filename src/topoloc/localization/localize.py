"""One drive's tokens -> raw, Strategy 1, Strategy 2 and HMM answers; tables and GeoJSON of the answers.

Shared by the ``decode_trajectories`` stage and the ``topoloc localize`` CLI.
The config slice is ``localization`` (see the schema): ``rnn`` (windows),
``decode`` (beam), ``hmm`` (baseline).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.localization.connectivity import DirectedEdges, directed_edges
from topoloc.localization.decoders import Decoded, beam_decode, decode_raw
from topoloc.localization.hmm import CellHMM, HmmParams
from topoloc.localization.rnn import edge_log_probs

#: Decoder names, in table order.
DECODERS = ("raw", "strategy1", "strategy2", "hmm")
LABELS = {"raw": "raw (argmax)", "strategy1": "Strategy 1", "strategy2": "Strategy 2", "hmm": "HMM baseline"}


@dataclass
class Localization:
    """The answers of every decoder for one drive, with the RNN's log-probabilities and timings."""

    decoded: dict[str, Decoded]
    logp: NDArray[np.float32]
    seconds: dict[str, float] = field(default_factory=dict)


class Localizer:
    """A trained RNN on a road graph with the decoders of ``conf`` (the ``localization`` config slice)."""

    def __init__(self, model: Any, graph: RoadGraph, conf: dict[str, Any], hmm: bool = True) -> None:
        self.model, self.graph, self.conf = model, graph, conf
        num_edges = int(model.hparams.num_edges) if hasattr(model, "hparams") else None
        if num_edges is not None and num_edges != graph.num_edges:
            raise InputError("model", f"the model predicts {num_edges} edge classes but the graph has {graph.num_edges} edges: "
                                      "a model trained on another map?")
        dec = conf["decode"]
        started = time.perf_counter()
        self.states: DirectedEdges = directed_edges(graph, dec["u_turns"], dec.get("max_skip_m"))
        self.setup_s = {"connectivity": time.perf_counter() - started}
        self.bins = int(model.hparams.bins) if hasattr(model, "hparams") else 20
        self.hmm: CellHMM | None = None
        if hmm:
            started = time.perf_counter()
            self.hmm = CellHMM(graph, self.states, self.bins, HmmParams.from_conf(conf.get("hmm")))
            self.setup_s["hmm"] = time.perf_counter() - started

    def beam_options(self) -> dict[str, Any]:
        dec = self.conf["decode"]
        return {"k": int(dec["k"]), "initial": dec["initial_hypotheses"], "score": dec["score"],
                "reseed": int(dec["reseed"]), "reseed_penalty": float(dec["reseed_penalty"])}

    def localize(self, tokens: NDArray[np.int64], decoders: tuple[str, ...] = DECODERS) -> Localization:
        """Run the RNN (windowed) and ``decoders`` on one drive's tokens."""
        tokens = np.asarray(tokens, np.int64)
        if len(tokens) == 0:
            raise ValueError("no tokens")
        if tokens.min() < 0 or tokens.max() >= self.bins:
            raise InputError("tokens", f"tokens must lie in [0, {self.bins}) for this model, got {tokens.min()}..{tokens.max()}")
        rnn = self.conf["rnn"]
        seconds: dict[str, float] = {}
        started = time.perf_counter()
        logp = edge_log_probs(self.model, tokens, rnn.get("window"), rnn.get("stride"))
        seconds["rnn"] = time.perf_counter() - started
        out: dict[str, Decoded] = {}
        options = self.beam_options()
        for name in decoders:
            started = time.perf_counter()
            if name == "raw":
                out[name] = decode_raw(logp)
            elif name in ("strategy1", "strategy2"):
                out[name] = beam_decode(logp, self.states, name, **options)
            elif name == "hmm":
                if self.hmm is None:
                    continue
                out[name] = self.hmm.decode(tokens)
            else:
                raise ValueError(f"unknown decoder {name!r}")
            seconds[name] = time.perf_counter() - started
        return Localization(out, logp, seconds)


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


def check_explained(result: Localization, min_share: float, where: str, min_turns: int = 8) -> None:
    """InputError when the HMM's best path explains too few of the drive's turns (heuristic, without a georeference)."""
    dec = result.decoded.get("hmm")
    if dec is None:
        return
    share = dec.extra.get("explained_turns", float("nan"))
    turns = dec.extra.get("turn_tokens", 0)
    if turns >= min_turns and np.isfinite(share) and share < min_share:
        raise InputError(where, f"nothing matches: the map turns where the drive does at only {share:.0%} of its {turns} turns "
                                f"(localization.min_explained_turns {min_share:.0%}); a drive for a different map?")


def decoded_table(tokens: pd.DataFrame, result: Localization) -> pd.DataFrame:
    """Per token: the input columns, then per decoder ``<name>_online``, ``<name>_path``, ``<name>_confidence``."""
    keep = [c for c in ("index", "token", "kind", "frame", "distance_m", "edge_id", "x", "y") if c in tokens.columns]
    table = tokens[keep].reset_index(drop=True).copy()
    if "edge_id" in table.columns:
        table = table.rename(columns={"edge_id": "true_edge_id"})
    for name, dec in result.decoded.items():
        table[f"{name}_online"] = dec.online
        table[f"{name}_path"] = dec.path
        table[f"{name}_confidence"] = np.round(dec.confidence, 4)
    return table


def write_table(path: str | Path, table: pd.DataFrame) -> None:
    """Write a decoded table as CSV, atomically."""
    with atomic_path(path) as tmp:
        table.to_csv(tmp, index=False, float_format="%.3f")


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


def write_geojson(path: str | Path, graph: RoadGraph, table: pd.DataFrame, decoder: str = "strategy1",
                  track_xy: NDArray[np.float64] | None = None) -> None:
    """GeoJSON (WGS84) of ``decoder``'s edge sequence: one LineString per run of one edge, and the track if given."""
    to_lonlat = _to_lonlat(graph)
    features = []
    path_edges = table[f"{decoder}_path"].to_numpy()
    distance = table["distance_m"].to_numpy() if "distance_m" in table.columns else np.arange(len(table), dtype=float)
    for order, (edge, first, last) in enumerate(runs_of(path_edges)):
        row = graph.edges.iloc[edge]
        features.append({
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": np.round(to_lonlat(graph.geometry[edge]), 7).tolist()},
            "properties": {"kind": "decoded_edge", "decoder": decoder, "order": order, "edge_id": edge,
                           "first_step": first, "last_step": last, "from_m": round(float(distance[first]), 1),
                           "to_m": round(float(distance[last]), 1), "name": str(row["name"]), "highway": str(row.highway),
                           "mean_confidence": round(float(table[f"{decoder}_confidence"].iloc[first:last + 1].mean()), 4)},
        })
    if track_xy is not None and len(track_xy) > 1:
        step = max(1, len(track_xy) // 2000)
        features.append({"type": "Feature", "properties": {"kind": "track"},
                         "geometry": {"type": "LineString", "coordinates": np.round(to_lonlat(track_xy[::step]), 7).tolist()}})
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps({"type": "FeatureCollection", "features": features}) + "\n")
