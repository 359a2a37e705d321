"""Paths -> token sequences and edge labels, streamed to Parquet.

Each path ``n_0 -e_0-> n_1 -e_1-> ... n_k`` is encoded with
:func:`topoloc.encoding.encode_segments` (the one convention shared with the
odometry of test drives): straight tokens at the virtual nodes of ``e_0``, the
turning-angle token at ``n_1``, the virtual nodes of ``e_1``, ... The label of a
token is the id of the real edge the vehicle is on after that step (the edge
"on which the last turn occurs"). Headings are taken from each road's polyline
oriented in the direction of travel, over ``heading_lookahead_m`` at its ends.

Rows are written to Parquet in row groups of ``shard_rows``: memory stays
bounded whatever the number of paths, and the bytes depend only on the inputs
and the seed.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from topoloc.encoding import encode_segments, polyline_end_headings
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.segmentation import segment_track, token_places
from topoloc.trajectory.paths import Path as GraphPath

SCHEMA = pa.schema(
    [
        ("path_id", pa.int64()),
        ("copy", pa.int16()),  # 0: the clean path; 1..: noisy augmented copies
        ("nodes", pa.list_(pa.int64())),
        ("edges", pa.list_(pa.int32())),
        ("tokens", pa.list_(pa.int16())),
        ("labels", pa.list_(pa.int32())),
        ("features", pa.list_(pa.float32())),  # per token, row-major (T x feature_dim); empty without features
    ]
)


@dataclass(frozen=True)
class Noise:
    """Augmentation: ``copies`` noisy versions of every training path."""

    copies: int = 0
    angle_std_deg: float = 0.0
    spacing_rel_std: float = 0.0


class PathEncoder:
    """Encodes paths of one road graph; per-edge lengths and headings are computed once.

    With ``segmentation`` (the config slice: ``tolerance_m``, ``corner_skip_m``,
    ``turn_label_offset_m``), a path is encoded like a test drive instead: its
    polyline goes through the Douglas-Peucker segmentation of
    :mod:`topoloc.segmentation`, so a straight-through
    intersection yields no token and a bend of a road can, as on real
    odometry; labels are the edge at each token's place along the path.
    """

    def __init__(self, graph: RoadGraph, bins: int, heading_lookahead_m: float, segmentation: dict | None = None) -> None:
        self.bins = bins
        self.graph = graph
        self.lookahead = heading_lookahead_m
        self.segmentation = segmentation
        self.spacing = graph.virtual_node_spacing_m
        self.lengths = graph.edges.length_m.to_numpy(dtype=float)
        self.u = graph.edges.u.to_numpy()
        # heading (start, end) of each edge travelled u->v; v->u is the reverse (+180, swapped).
        self.forward = np.array([polyline_end_headings(g, heading_lookahead_m) for g in graph.geometry]).reshape(-1, 2)

    def headings(self, path: GraphPath) -> tuple[np.ndarray, np.ndarray]:
        """Travel headings at the start and end of each edge of ``path``, in degrees."""
        edges = np.asarray(path.edges)
        reverse = self.u[edges] != np.asarray(path.nodes[:-1])
        start = np.where(reverse, self.forward[edges, 1] + 180.0, self.forward[edges, 0])
        end = np.where(reverse, self.forward[edges, 0] + 180.0, self.forward[edges, 1])
        return start, end

    def encode(self, path: GraphPath, rng: np.random.Generator | None = None, noise: Noise = Noise()) -> tuple[np.ndarray, np.ndarray]:
        """Tokens and edge-id labels of ``path``; with ``rng``, jittered by ``noise``."""
        if self.segmentation is not None:
            return self._encode_segmented(path, rng, noise)
        edges = np.asarray(path.edges)
        lengths = self.lengths[edges]
        start, end = self.headings(path)
        if rng is not None:
            start = start + rng.normal(0.0, noise.angle_std_deg, len(start)) if noise.angle_std_deg else start
            if noise.spacing_rel_std:
                lengths = lengths * np.clip(1.0 + rng.normal(0.0, noise.spacing_rel_std, len(lengths)), 0.1, None)
        drive = encode_segments(lengths, start, end, self.spacing, self.bins)
        return drive.tokens, edges[drive.segment]


    def _encode_segmented(self, path: GraphPath, rng: np.random.Generator | None, noise: Noise) -> tuple[np.ndarray, np.ndarray]:
        edges = np.asarray(path.edges)
        pieces = [self.graph.edge_coords(int(edges[0]), path.nodes[0])]
        pieces += [self.graph.edge_coords(int(e), n)[1:] for e, n in zip(edges[1:], path.nodes[1:-1])]
        seg_conf = self.segmentation
        seg = segment_track(np.vstack(pieces), float(seg_conf["tolerance_m"]), self.lookahead,
                            corner_skip_m=float(seg_conf["corner_skip_m"]))
        lengths, start, end = seg["lengths"], seg["heading_start"], seg["heading_end"]
        if rng is not None:
            start = start + rng.normal(0.0, noise.angle_std_deg, len(start)) if noise.angle_std_deg else start
            if noise.spacing_rel_std:
                lengths = lengths * np.clip(1.0 + rng.normal(0.0, noise.spacing_rel_std, len(lengths)), 0.1, None)
        drive = encode_segments(lengths, start, end, self.spacing, self.bins)
        # places along the true path: a jittered segment's tokens are spread over its true length
        scale = seg["lengths"] / np.maximum(lengths, 1e-9)
        place, _ = token_places(drive, seg["cum"][seg["corners"]], seg["lengths"], self.spacing * scale,
                                float(seg_conf["turn_label_offset_m"]))
        ends = np.cumsum(self.lengths[edges])
        return drive.tokens, edges[np.minimum(np.searchsorted(ends, place, side="right"), len(edges) - 1)]


class ShardWriter:
    """Appends rows to a Parquet file, one row group per ``shard_rows`` rows."""

    def __init__(self, path: str | Path, shard_rows: int) -> None:
        self.writer = pq.ParquetWriter(str(path), SCHEMA, compression="zstd")
        self.shard_rows = shard_rows
        self.rows: dict[str, list] = {name: [] for name in SCHEMA.names}
        self.count = 0

    def add(self, path_id: int, copy: int, path: GraphPath, tokens: np.ndarray, labels: np.ndarray,
            features: np.ndarray | None = None) -> None:
        flat = np.zeros(0, np.float32) if features is None else np.asarray(features, np.float32).ravel()
        for name, value in zip(SCHEMA.names, (path_id, copy, path.nodes, path.edges, tokens, labels, flat)):
            self.rows[name].append(value)
        self.count += 1
        if len(self.rows["path_id"]) >= self.shard_rows:
            self.flush()

    def flush(self) -> None:
        if self.rows["path_id"]:
            self.writer.write_table(pa.table(self.rows, schema=SCHEMA))
            self.rows = {name: [] for name in SCHEMA.names}

    def close(self) -> None:
        self.flush()
        self.writer.close()


def iter_rows(path: str | Path, columns: Iterable[str] = ("tokens", "labels")) -> Iterator[dict]:
    """Rows of a dataset file, one row group at a time."""
    file = pq.ParquetFile(str(path))
    for group in range(file.num_row_groups):
        yield from file.read_row_group(group, columns=list(columns)).to_pylist()


def load_sequences(path: str | Path, limit: int | None = None) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Tokens and labels of (the first ``limit``) rows of a dataset file, as numpy arrays."""
    table = pq.read_table(str(path), columns=["tokens", "labels"])
    if limit is not None:
        table = table.slice(0, limit)
    tokens = table.column("tokens").combine_chunks()
    labels = table.column("labels").combine_chunks()
    offsets = tokens.offsets.to_numpy()
    offsets = offsets - offsets[0]
    flat_t = tokens.flatten().to_numpy().astype(np.int64)
    flat_l = labels.flatten().to_numpy().astype(np.int64)
    return ([flat_t[a:b] for a, b in zip(offsets[:-1], offsets[1:])],
            [flat_l[a:b] for a, b in zip(offsets[:-1], offsets[1:])])


def load_features(path: str | Path, dim: int, limit: int | None = None) -> list[np.ndarray]:
    """Per row of a dataset file, its continuous features ``(T, dim)`` (float32)."""
    table = pq.read_table(str(path), columns=["tokens", "features"])
    if limit is not None:
        table = table.slice(0, limit)
    column = table.column("features").combine_chunks()
    offsets = column.offsets.to_numpy()
    offsets = offsets - offsets[0]
    flat = column.flatten().to_numpy().astype(np.float32)
    out = [flat[a:b].reshape(-1, dim) for a, b in pairwise(offsets)]
    lengths = [len(t) for t in table.column("tokens").to_pylist()]
    bad = next((i for i, (f, n) in enumerate(zip(out, lengths)) if len(f) != n), None)
    if bad is not None:
        raise InputError(str(path), f"row {bad} has {len(out[bad])} feature rows of {dim} for {lengths[bad]} tokens")
    return out


MAX_OFFSET = 31  # offsets along an edge beyond this share the last class


def state_targets(nodes: list[int], edges: list[int], labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-step travel direction and offset along the current edge, the rest of the position a label leaves out.

    Direction is 1 when the edge is travelled towards the higher node id (any
    fixed orientation of each edge would do); the offset counts the steps
    since the vehicle entered the edge (0 at the turn onto it), capped at
    :data:`MAX_OFFSET`. Used as auxiliary training targets.
    """
    index = {edge: i for i, edge in enumerate(edges)}
    labels = np.asarray(labels)
    step = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])  # first step on each edge
    run = np.repeat(step, np.diff(np.r_[step, len(labels)]))
    offsets = np.minimum(np.arange(len(labels)) - run, MAX_OFFSET)
    position = np.array([index[int(edge)] for edge in labels[step]])
    forward = np.asarray(nodes)[position] < np.asarray(nodes)[position + 1]
    directions = np.repeat(forward.astype(np.int64), np.diff(np.r_[step, len(labels)]))
    return directions, offsets.astype(np.int64)


def load_state_targets(path: str | Path, limit: int | None = None) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """:func:`state_targets` of (the first ``limit``) rows of a dataset file."""
    directions, offsets = [], []
    for count, row in enumerate(iter_rows(path, ("nodes", "edges", "labels"))):
        if limit is not None and count >= limit:
            break
        d, o = state_targets(row["nodes"], row["edges"], np.asarray(row["labels"]))
        directions.append(d)
        offsets.append(o)
    return directions, offsets
