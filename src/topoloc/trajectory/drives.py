"""Training drives like test drives: simulated odometry on the map, segmented and encoded as a real drive is.

The dataset source ``simulated_drives`` (config ``dataset.simulated``): each training row is one drive
made as :func:`topoloc.odometry.simulate.simulate_pattern_drive` makes its ``random`` drives (a random walk on the
map, one-way roads respected, no U-turn but at a dead end where the walk is cut; driven the way a car
does with :func:`topoloc.motion.route.smooth_path`: in the right-hand lane, corners rounded, a frame about
every metre) of a length drawn from ``length_m``, whose odometry goes through the one noise model
(:func:`topoloc.motion.noise.integrate_odometry`) with parameters drawn per drive from the ranges of
``noise``. The walk is drawn by :class:`Walker` on arrays (the graph's pandas tables make
:func:`topoloc.motion.route.random_route` ten times slower, which matters for thousands of drives). The first ``U(0, crop_m)`` metres are cut off, so a row starts anywhere on a
road, not only at an intersection (the model learns to localize from any start). The odometry is then
segmented and encoded by :func:`topoloc.segmentation.encode_odometry`, the very function that
makes the tokens of a test drive for the localizers (Douglas-Peucker of ``segmentation``, then
:mod:`topoloc.encoding`), which also gives each token's continuous features
(:func:`topoloc.segmentation.token_features`). The label of a token is the true road at its frame.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.noise import NOISE_KEYS, OdometryNoise, integrate_odometry
from topoloc.motion.route import DENSE_M, sample_route, smooth_path
from topoloc.odometry.simulate import NoiseLevel
from topoloc.segmentation import encode_odometry


class Walker:
    """Random walks on a road graph as :func:`topoloc.motion.route.random_route` draws them, on arrays."""

    def __init__(self, graph: RoadGraph) -> None:
        u, v = graph.edges.u.to_numpy(), graph.edges.v.to_numpy()
        oneway = graph.edges.oneway.to_numpy()
        self.length = graph.edges.length_m.to_numpy(dtype=float)
        self.options: dict[int, list[tuple[int, int]]] = {int(n): [] for n in graph.nodes.index}
        for key, (a, b, ow) in enumerate(zip(u, v, oneway)):
            if ow != -1:
                self.options[int(a)].append((key, int(b)))
            if ow != 1 and a != b:
                self.options[int(b)].append((key, int(a)))
        degree = graph.nodes.degree
        self.starts = [int(n) for n in graph.nodes.index if degree.at[n] >= 2] or [int(n) for n in graph.nodes.index]

    def walk(self, length_m: float, rng: np.random.Generator, max_steps: int = 10000) -> tuple[list[int], list[int]]:
        """Roads and the node each is entered from, at least ``length_m`` long unless cut at a dead end."""
        node = int(rng.choice(self.starts))
        route: list[int] = []
        froms: list[int] = []
        total = 0.0
        for _ in range(max_steps):
            options = [(k, n) for k, n in self.options[node] if not route or k != route[-1]]
            if not options:
                break  # a dead end: a camera path cannot turn on the spot, the walk ends here
            key, nxt = options[int(rng.integers(len(options)))]
            route.append(key)
            froms.append(node)
            total += self.length[key]
            node = nxt
            if total >= length_m:
                break
        return route, froms

    def longest(self, length_m: float, rng: np.random.Generator, attempts: int = 50) -> tuple[list[int], list[int]]:
        """The first of up to ``attempts`` walks that reaches ``length_m``, else the longest."""
        best: tuple[list[int], list[int]] = ([], [])
        best_len = -1.0
        for _ in range(attempts):
            route, froms = self.walk(length_m, rng)
            total = float(self.length[route].sum()) if route else 0.0
            if total > best_len:
                best, best_len = (route, froms), total
            if total >= length_m:
                break
        return best


@dataclass(frozen=True)
class TrainingDrive:
    """One encoded training drive: the walk (nodes, roads), tokens, labels (road per token), features."""

    nodes: list[int]
    edges: list[int]
    tokens: NDArray[np.int64]
    labels: NDArray[np.int64]
    features: NDArray[np.float32]
    length_m: float


def noise_level(ranges: Mapping[str, Any]) -> NoiseLevel:
    """The per-drive noise ranges of ``dataset.simulated.noise`` as a :class:`NoiseLevel`."""
    pairs = {}
    for key in NOISE_KEYS:
        low, high = (float(v) for v in ranges[key])
        if not 0 <= low <= high:
            raise InputError(f"dataset.simulated.noise.{key}", f"expected [low, high] with 0 <= low <= high, got {ranges[key]}")
        pairs[key] = (low, high)
    return NoiseLevel("training", **pairs)


def training_drive(graph: RoadGraph, walker: Walker, conf: dict[str, Any], level: NoiseLevel,
                   rng: np.random.Generator) -> TrainingDrive | None:
    """One simulated, cropped, encoded drive (module docstring); None when it yields fewer than two tokens."""
    sim = conf["dataset"]["simulated"]
    low, high = (float(v) for v in sim["length_m"])
    crop = float(rng.uniform(0.0, float(sim["crop_m"])))
    length = float(rng.uniform(low, high)) + crop
    route, froms = walker.longest(length + 20.0, rng)
    if not route:
        return None
    dense, dense_edge = sample_route(graph, route, froms, DENSE_M)
    xy, yaw, edge = smooth_path(dense, dense_edge, 1.0, 4.0, 1.5, 3.0)  # as odometry.simulate.simulate_pattern_drive
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    keep = cum <= length
    xy, yaw, edge, cum = xy[keep], yaw[keep], edge[keep], cum[keep]
    first = int(np.searchsorted(cum, crop))
    if len(xy) - first < 3:
        return None
    odo = integrate_odometry(xy[first:], yaw[first:], OdometryNoise.from_dict(level.draw(rng)), rng)
    track, features = encode_odometry(odo.xy, odo.yaw, graph.virtual_node_spacing_m, int(conf["encoding"]["angle_bins"]), conf)
    if len(track.encoded.tokens) < 2:
        return None
    labels = edge[first:][np.asarray(track.frame, np.int64)]
    nodes = [*froms, graph.other_end(route[-1], froms[-1])]
    return TrainingDrive([int(n) for n in nodes], [int(e) for e in route], np.asarray([int(t) for t in track.encoded.tokens], np.int64),
                         labels.astype(np.int64), features, float(cum[-1] - cum[first]))


def training_drives(graph: RoadGraph, conf: dict[str, Any], seed: int) -> Iterator[TrainingDrive]:
    """``dataset.simulated.drives`` training drives of ``graph`` from ``seed`` (same seed, same drives)."""
    sim = conf["dataset"]["simulated"]
    level = noise_level(sim["noise"])
    walker = Walker(graph)
    rng = np.random.default_rng([seed, 3])
    made = tries = 0
    while made < int(sim["drives"]):
        tries += 1
        if tries > 2 * int(sim["drives"]) + 100:
            raise InputError("dataset.simulated.length_m", f"only {made} of {tries} simulated drives gave two tokens or more "
                                                          "on this map: roads too short for the drive lengths?")
        drive = training_drive(graph, walker, conf, level, rng)
        if drive is not None:
            made += 1
            yield drive
