"""The topometric map of a teach drive (Cai & Wan, Sec. 3.4) and the ``build_topometric_map`` stage.

One vertex per teach frame holds

* the **image embedding** of the siamese network's backbone (and the raw-correlation descriptor of the
  baseline);
* the **position** from path integration of the teach drive's noisy odometry
  (:mod:`topoloc.place.odometry`), and its arc length ``s`` along the vertex chain (the metric coordinate
  the localization integrates in);
* the **navigation command** (the paper's discrete local move): ``left``, ``right`` or ``straight`` when
  the next intersection of the route (a graph node of degree 3 or more where the route changes road) is
  within ``command.distance_m`` ahead, else ``follow`` (the lane). The turn is the manoeuvre the vehicle
  makes while it is told: the drive's heading change from where the command is first shown
  (``command.distance_m`` before the intersection, or the previous intersection) to ``command.lookahead_m``
  past it, as a turning angle (:func:`topoloc.geometry.turning_angle`: 180 straight, 90 left, 270 right);
  within ``command.straight_deg`` of 180 it is ``straight``. So a sharp bend of the approach counts: a route
  that bends 67 deg right into a junction it then crosses straight on is told ``right``, not ``straight``
  (the junction's own angle, read from the graph, would tell a Topo-DLM to drive straight through the bend).

The ground-truth position of each vertex is kept for evaluation only. The stage is
:mod:`topoloc.place.build_topometric_map`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.geometry import heading_change
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.place.images import PlaceSet
from topoloc.place.odometry import noisy_odometry
from topoloc.place.topometric_localization import correlation_descriptors

COMMANDS = ("follow", "left", "right", "straight")


@dataclass
class TopometricMap:
    """Vertices of a teach drive; see the module docstring. ``command`` holds indices into :data:`COMMANDS`."""

    embedding: NDArray[np.float32]
    descriptor: NDArray[np.float32]
    xy: NDArray[np.float64]
    command: NDArray[np.int64]
    gt_xy: NDArray[np.float64]
    condition: str

    @property
    def s(self) -> NDArray[np.float64]:
        """Arc length of each vertex along the path-integrated chain."""
        return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.xy, axis=0).T))])

    def __len__(self) -> int:
        return len(self.xy)

    def part(self, lo: int, hi: int) -> TopometricMap:
        """The map of vertices ``lo`` to ``hi - 1`` (a teach drive of that stretch alone)."""
        return TopometricMap(self.embedding[lo:hi], self.descriptor[lo:hi], self.xy[lo:hi], self.command[lo:hi],
                             self.gt_xy[lo:hi], self.condition)

    def save(self, path: str | Path) -> None:
        """Write as ``.npz``, atomically."""
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as handle:
                np.savez(handle, embedding=self.embedding, descriptor=self.descriptor, xy=self.xy, command=self.command,
                         gt_xy=self.gt_xy, condition=np.array(self.condition))

    @classmethod
    def load(cls, path: str | Path) -> TopometricMap:
        """Read a map written by :meth:`save`; InputError naming the file otherwise."""
        try:
            with np.load(path) as data:
                return cls(data["embedding"], data["descriptor"], data["xy"], data["command"].astype(np.int64),
                           data["gt_xy"], str(data["condition"]))
        except (OSError, KeyError, ValueError) as err:
            raise InputError(path, f"not a topometric map ({err})") from err


@dataclass(frozen=True)
class Intersection:
    """A route's passage through an intersection: first frame on the exit road, node, command, turning angle."""

    frame: int
    node: int
    command: str
    angle_deg: float


def _shared_node(graph: RoadGraph, e1: int, e2: int, xy: NDArray[np.float64]) -> int:
    """The node where the route passes from edge ``e1`` to ``e2`` (the common end nearest to ``xy``)."""
    ends1 = {int(graph.edges.u.iat[e1]), int(graph.edges.v.iat[e1])}
    ends2 = {int(graph.edges.u.iat[e2]), int(graph.edges.v.iat[e2])}
    candidates = sorted(ends1 & ends2) or sorted(ends1 | ends2)
    pos = graph.nodes.loc[candidates, ["x", "y"]].to_numpy(float)
    return candidates[int(np.argmin(np.hypot(*(pos - xy).T)))]


def classify_turn(angle_deg: float, straight_deg: float) -> str:
    """``straight`` within ``straight_deg`` of 180 degrees, else ``left`` (below) or ``right`` (above)."""
    if abs(angle_deg - 180.0) <= straight_deg:
        return "straight"
    return "left" if angle_deg < 180.0 else "right"


def drive_heading_change(xy: NDArray[np.float64], s_from: float, s_to: float, step_m: float = 1.0) -> float:
    """Counter-clockwise heading change (degrees, left positive, not wrapped) of a drive ``xy`` between arc
    lengths ``s_from`` and ``s_to``: from its chord over the first ``step_m`` to its chord over the last, summed
    over chords of ``step_m`` (robust to frames that repeat a position while the vehicle stands)."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    keep = np.concatenate([[True], np.diff(cum) > 0])
    cum, pts = cum[keep], xy[keep]
    lo, hi = max(0.0, s_from), min(float(cum[-1]), s_to)
    if hi - lo < 2 * step_m:
        return 0.0
    at = np.linspace(lo, hi, round((hi - lo) / step_m) + 1)
    samples = np.column_stack([np.interp(at, cum, pts[:, 0]), np.interp(at, cum, pts[:, 1])])
    return float(np.sum(heading_change(samples[:-2], samples[1:-1], samples[2:])))


def route_intersections(graph: RoadGraph, edge: NDArray[np.int64], xy: NDArray[np.float64], lookahead_m: float,
                        straight_deg: float, distance_m: float) -> list[Intersection]:
    """Intersections a drive passes, from its per-frame road edges ``edge`` and positions ``xy``; each classed by
    the drive's heading change from ``distance_m`` before it (or the previous intersection) to ``lookahead_m``
    past it (see the module docstring)."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    out: list[Intersection] = []
    for k in np.flatnonzero(np.diff(edge) != 0) + 1:
        e1, e2 = int(edge[k - 1]), int(edge[k])
        if e1 < 0 or e2 < 0:
            continue
        node = _shared_node(graph, e1, e2, xy[k])
        if int(graph.nodes.degree.at[node]) < 3:
            continue  # a bend or a change of one-way direction, not an intersection
        shown = max(cum[k] - distance_m, cum[out[-1].frame] if out else 0.0)
        angle = float(np.mod(180.0 - drive_heading_change(xy, shown, cum[k] + lookahead_m), 360.0))
        out.append(Intersection(int(k), node, classify_turn(angle, straight_deg), angle))
    return out


def vertex_commands(xy: NDArray[np.float64], intersections: list[Intersection], distance_m: float) -> NDArray[np.int64]:
    """Command index per frame: that of the next intersection when it is within ``distance_m`` ahead, else follow."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    command = np.zeros(len(xy), np.int64)
    previous = 0
    for item in intersections:
        ahead = np.arange(previous, item.frame)
        near = ahead[cum[item.frame] - cum[ahead] <= distance_m]
        command[near] = COMMANDS.index(item.command)
        previous = item.frame
    return command


def teach_vertices(images: NDArray[np.uint8], embedding: NDArray[np.float32], xy: NDArray[np.float64],
                   yaw: NDArray[np.float64], command: NDArray[np.int64], condition: str, conf: dict[str, Any],
                   seed: int) -> tuple[TopometricMap, float]:
    """The map of teach frames (their images, embeddings, true poses and commands; ``conf`` the ``place`` slice): the
    raw-correlation descriptors, and the positions from path integration of the odometry through the noise model of
    ``place.odometry_noise`` drawn from ``seed``; and the drawn scale error."""
    descriptor = correlation_descriptors(images, tuple(conf["localize"]["correlation_size"]))
    odometry, scale_error = noisy_odometry(xy, yaw, conf["odometry_noise"], np.random.default_rng([int(seed), 23]))
    return TopometricMap(embedding.astype(np.float32), descriptor, odometry.xy, command, xy, condition), scale_error


def build_map(teach: PlaceSet, graph: RoadGraph, model: Any, conf: dict[str, Any]) -> tuple[TopometricMap, list[Intersection], dict[str, float]]:
    """The map of the teach set's single condition; ``conf`` is the ``place`` config slice."""
    if len(teach.conditions) != 1:
        raise InputError("place.teach_condition", f"the teach set must hold one condition, got {teach.conditions}")
    if np.any(teach.edge < 0):
        raise InputError("teach", "the teach set lacks the road edge of some frames")
    images = teach.images[0]
    started = time.perf_counter()
    embedding = model.embed(images)
    embed_s = time.perf_counter() - started
    cmd = conf["command"]
    crossings = route_intersections(graph, teach.edge, teach.xy, float(cmd["lookahead_m"]), float(cmd["straight_deg"]),
                                    float(cmd["distance_m"]))
    command = vertex_commands(teach.xy, crossings, float(cmd["distance_m"]))
    topo, scale_error = teach_vertices(images, embedding, teach.xy, teach.yaw, command, teach.conditions[0], conf,
                                       int(conf["seed"]))
    drift = np.hypot(*(topo.xy - teach.xy).T)
    facts = {"vertices": float(len(topo)), "length_m": float(topo.s[-1]),
             "true_length_m": float(np.hypot(*np.diff(teach.xy, axis=0).T).sum()),
             "scale_error": scale_error, "drift_end_m": float(drift[-1]), "drift_max_m": float(drift.max()),
             "intersections": float(len(crossings)), "embed_s": embed_s, "embed_images_per_s": len(images) / max(embed_s, 1e-9),
             **{f"vertices_{name}": float(np.sum(command == i)) for i, name in enumerate(COMMANDS)}}
    return topo, crossings, facts
