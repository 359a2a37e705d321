"""The metric filter: a Bayes filter over positions on directed roads, driven by the odometry itself.

After Brubaker, Geiger and Urtasun ("Lost! Leveraging the crowd for probabilistic visual
self-localization", CVPR 2013; PAMI 2016), on our cells (:mod:`topoloc.localization.cells`):

* **Input**: the odometry as planar poses (position and yaw in any frame; the filter never uses
  the frame's orientation or origin). It is cut into *steps*: each time the odometry has driven
  ``cell_m`` metres further along its heading (forward) or back (reversing) one step is taken,
  with the odometry's yaw at that moment. A vehicle that stands still makes no step.
* **State**: a probability per cell, and per cell a belief about the *heading offset* ``theta``
  between the odometry frame and the map (a von Mises distribution: mean and concentration), plus
  one *off-map* state for "on no road of this map".
* **Motion**: a forward step moves every cell ``cell_m`` along the road network (onto every road
  that may follow at a node, equal shares; one-way roads respected), blurred by ``step_jitter``
  (the share that moves zero or two cells: the odometry's scale error); a backward step moves
  along the roads that lead into the cell. Where several cells flow into one, their ``theta``
  beliefs merge (moment matching on the circle); ``theta`` diffuses by ``offset_drift_deg`` per
  square root of 100 m (heading drift of the odometry and slowly varying map error).
* **Evidence**: the odometry's yaw against the map road's heading at the cell plus ``theta``:
  von Mises with the spread ``heading_sigma_deg`` (plus, on a turn chain, ``turn_sigma_share`` of
  the turn angle at the node, fading out towards the ends of the turn: vehicles round a corner
  more or less widely than the modelled sweep), mixed with a uniform ``floor``. Curves therefore count as much as corners, and driving straight
  through an intersection gives no false turn. Each observation also sharpens ``theta``.
* **Off the map**: the off-map state predicts the heading without a map: the last one plus the
  noise of two observations, or, with ``offmap_turn_prob``, anything (a turn). It wins where the
  drive turns as no road does and loses where a road explains the turn; mass moves there with
  ``leave_prob`` per step and comes back, spread over the whole map, with ``enter_prob``. A drive
  the map cannot explain ends there (low confidence) instead of collapsing onto a wrong road, and
  is found again when it returns.

* **Scale**: once the belief is no longer broad it splits into ``scale_classes`` groups of odometry
  scale error up to ``scale_error_max``, each moving ``1 / (1 + s)`` cells a step
  (:mod:`topoloc.localization.metric_filter`), so lengths count even when the odometry's are off
  by a few percent.

The online answer after each step is the road (undirected edge) with the largest probability,
its best cell (position) and that probability (confidence). The filter also traces a consistent
path back (:meth:`~topoloc.localization.metric_filter.MetricFilter.trace`). This module holds the
settings, the odometry steps and the map model; the belief is in
:mod:`topoloc.localization.metric_filter`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.cells import CellGrid
from topoloc.localization.connectivity import DirectedEdges
from topoloc.localization.lanes import lane_chains

TWO_PI = 2.0 * math.pi
INT_SETTINGS = ("scale_classes", "coarse_factor", "coarse_min_cells", "coarse_handoff_cells")


@dataclass(frozen=True)
class MetricSettings:
    """Settings of the metric filter (config ``localization.metric``)."""

    cell_m: float
    turn_zone_m: float
    heading_window_m: float
    heading_sigma_deg: float
    turn_sigma_share: float
    offset_drift_deg: float
    step_jitter: float
    floor: float
    offmap_turn_prob: float
    offmap_prior: float
    leave_prob: float
    enter_prob: float
    prune: float
    scale_error_max: float
    scale_classes: int
    coarse_factor: int = 1
    coarse_min_cells: int = 0
    coarse_handoff_cells: int = 100000
    coarse_spread: float = 1.0

    @classmethod
    def from_conf(cls, conf: dict) -> MetricSettings:
        """The settings of the validated config slice ``localization.metric``."""
        return cls(**{k: (int if k in INT_SETTINGS else float)(conf[k]) for k in cls.__dataclass_fields__})


@dataclass(frozen=True)
class Steps:
    """The odometry cut into steps of ``step_m``: direction (+1 forward, -1 back), yaw (radians) and frame."""

    direction: NDArray[np.int64]
    yaw: NDArray[np.float64]
    frame: NDArray[np.int64]
    driven_m: NDArray[np.float64]  #: absolute distance driven up to the step, metres

    def __len__(self) -> int:
        return len(self.direction)


def odometry_steps(xy: NDArray[np.float64], yaw: NDArray[np.float64], step_m: float) -> Steps:
    """Steps of ``step_m`` metres of the planar odometry ``xy`` (n, 2), ``yaw`` (n,) radians.

    The signed distance of a frame is its displacement along the mean yaw of its two poses (negative
    when reversing); a step is taken each time the signed arc length crosses the next multiple of
    ``step_m`` up or down, with the yaw interpolated there.
    """
    xy = np.asarray(xy, float)
    yaw = np.unwrap(np.asarray(yaw, float))
    if len(xy) < 2:
        return Steps(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64), np.zeros(0))
    move = np.diff(xy, axis=0)
    mid = 0.5 * (yaw[1:] + yaw[:-1])
    ds = move[:, 0] * np.cos(mid) + move[:, 1] * np.sin(mid)
    s = np.concatenate([[0.0], np.cumsum(ds)])
    driven = np.concatenate([[0.0], np.cumsum(np.abs(ds))])
    direction, yaws, frames, dist = [], [], [], []
    level = 0
    for k in range(1, len(s)):
        while s[k] >= (level + 1) * step_m or s[k] <= (level - 1) * step_m:
            up = s[k] >= (level + 1) * step_m
            level += 1 if up else -1
            target = level * step_m
            frac = (target - s[k - 1]) / (s[k] - s[k - 1]) if s[k] != s[k - 1] else 1.0
            direction.append(1 if up else -1)
            yaws.append(yaw[k - 1] + frac * (yaw[k] - yaw[k - 1]))
            frames.append(k)
            dist.append(driven[k - 1] + frac * (driven[k] - driven[k - 1]))
    return Steps(np.asarray(direction, np.int64), np.asarray(yaws), np.asarray(frames, np.int64), np.asarray(dist))


def resultant_length(kappa: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean resultant length of a von Mises of concentration ``kappa``, ``kappa / (0.5 + sqrt(kappa^2 + 4))``:
    within 0.02 of ``I1 / I0`` from kappa 5 on, with the right limits, and exactly inverted by :func:`concentration`."""
    return kappa / (0.5 + np.sqrt(kappa * kappa + 4.0))


def concentration(r: NDArray[np.float64]) -> NDArray[np.float64]:
    """The concentration whose :func:`resultant_length` is ``r`` (in [0, 1))."""
    r = np.asarray(r)
    r = np.minimum(r, 1.0 - 4.0 * np.finfo(r.dtype if r.dtype.kind == "f" else np.float64).eps)
    q = 1.0 - r * r
    return r * (1.0 + np.sqrt(1.0 + 15.0 * q)) / (2.0 * q)


def _transitions(grid: CellGrid, distance_m: float) -> sp.csr_matrix:
    """Moves of ``distance_m`` as a CSR matrix with one row per source cell."""
    moves = grid.moves(distance_m)
    n = grid.num_cells
    return sp.csr_matrix((moves.weight, (moves.src, moves.dst)), shape=(n, n))


class MetricModel:
    """What the filter needs of a map, built once: the cells (with turn chains) and the step transitions."""

    def __init__(self, graph: RoadGraph, states: DirectedEdges, settings: MetricSettings) -> None:
        self.settings = settings
        chains = lane_chains(graph, states, settings.turn_zone_m, settings.heading_window_m)
        self.grid = grid = CellGrid(graph, states, chains, settings.cell_m, settings.heading_window_m)
        n = grid.num_cells
        p = settings.step_jitter
        one = _transitions(grid, settings.cell_m)
        two = _transitions(grid, 2.0 * settings.cell_m)
        self.forward = (p * sp.identity(n, format="csr") + (1.0 - 2.0 * p) * one + p * two).tocsr().astype(np.float32)
        back = one.T.tocsr()  # rows: the cell a backward step starts from; columns: where it came from
        norm = np.asarray(back.sum(axis=1)).ravel()
        self.backward = (sp.diags(1.0 / np.maximum(norm, 1e-12)) @ back).tocsr().astype(np.float32)
        self.forward_cols, self.backward_cols = self.forward.T.tocsr(), self.backward.T.tocsr()
        sigma = np.radians(settings.heading_sigma_deg)
        turning = settings.turn_sigma_share * grid.turn_ramp  # how a vehicle turns varies: the more, the sharper the turn
        self.kappa_obs = (1.0 / (sigma**2 + turning**2)).astype(np.float32)  # von Mises concentration of one observation
        self.unheading = np.exp(-1j * np.radians(grid.heading)).astype(np.complex64)  # e^{-i h}: a yaw into an offset
        self.drift = float(np.radians(settings.offset_drift_deg) ** 2 * settings.cell_m / 100.0)  # variance per step
        # off the map the heading is its last value plus the noise of two observations, or anything (a turn)
        self.offmap_kappa = 1.0 / (2.0 * sigma**2)
        self.floor_density = settings.floor / TWO_PI
        k = max(1, int(settings.scale_classes))
        self.scales = np.linspace(-settings.scale_error_max, settings.scale_error_max, k) if k > 1 else np.zeros(1)
        spread = settings.scale_error_max / 2.0 if settings.scale_error_max > 0 else 1.0
        prior = np.exp(-0.5 * (self.scales / spread) ** 2)
        self.scale_prior = prior / prior.sum()

    def offmap_density(self, turn: NDArray[np.float64]) -> NDArray[np.float64]:
        """Density of a heading change ``turn`` (radians, per step) off the map; NaN (no last heading): uniform."""
        p = self.settings.offmap_turn_prob
        straight = np.exp(self.offmap_kappa * (np.cos(turn) - 1.0)) * math.sqrt(self.offmap_kappa / TWO_PI + 1.0 / TWO_PI**2)
        return np.where(np.isfinite(turn), (1.0 - p) * straight + p / TWO_PI, 1.0 / TWO_PI)

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells
