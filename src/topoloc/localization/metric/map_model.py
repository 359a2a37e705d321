"""The metric filter's settings and its model of a map, built once per map and settings.

:class:`MetricModel` holds the cells (:mod:`topoloc.localization.metric.cell_grid`, on the chains of
:mod:`topoloc.localization.metric.lane_chains`), the *motion model* (the transitions of a forward and a
backward step, blurred by ``step_jitter``; the scale classes) and the *measurement model* (the concentration
of one heading observation per cell, the map heading, the off-map heading density). The package docstring
(:mod:`topoloc.localization.metric`) describes the filter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.connectivity import DirectedEdges
from topoloc.localization.metric.cell_grid import CellGrid
from topoloc.localization.metric.lane_chains import lane_chains

TWO_PI = 2.0 * math.pi
INT_SETTINGS = ("scale_classes", "coarse_factor", "coarse_min_cells", "coarse_handoff_cells")
STR_SETTINGS = ("branches", "u_turns", "turn_path", "turn_spread")
BOOL_SETTINGS = ("bend_spread",)


@dataclass(frozen=True)
class AddedRoads:
    """Per state of a map with roads added: ``origin``, the map's road it answers as; ``weight``, 1 for the map's own
    roads, less for an added one (``merge_duals_weight``); ``roads``: how many roads the map has."""

    origin: NDArray[np.int64]
    weight: NDArray[np.float64]
    roads: int


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
    coarse_handoff_share: float = 1.0
    coarse_spread: float = 1.0
    branches: str = "equal"
    node_offset_deg: float = 0.0
    u_turns: str = "always"
    u_turn_weight: float = 0.3
    turn_path: str = "node"
    wide_zone_m: float = 20.0
    wide_share: float = 0.1
    u_turn_gap_m: float = 17.5
    merge_duals_m: float = 25.0
    merge_duals_weight: float = 0.01
    lateral_offset_m: float = 0.0
    turn_spread: str = "density"
    bend_spread: bool = True
    offmap_spread: float = 1.0

    @classmethod
    def from_conf(cls, conf: dict) -> MetricSettings:
        """The settings of the validated config slice ``localization.metric``."""
        return cls(**{k: (str if k in STR_SETTINGS else int if k in INT_SETTINGS else bool if k in BOOL_SETTINGS
                          else float)(conf[k]) for k in cls.__dataclass_fields__})


def _transitions(grid: CellGrid, distance_m: float, split: bool = True) -> sp.csr_matrix:
    """Moves of ``distance_m`` as a CSR matrix with one row per source cell (``split``: see ``CellGrid.moves``)."""
    moves = grid.moves(distance_m, split)
    n = grid.num_cells
    return sp.csr_matrix((moves.weight, (moves.src, moves.dst)), shape=(n, n))


class MetricModel:
    """What the filter needs of a map, built once: the cells (with turn chains) and the step transitions;
    ``lane_offset_m`` places the cells' positions (:func:`~topoloc.localization.metric.cell_grid.lane_offsets`);
    ``added``: roads added to the map (:mod:`~topoloc.localization.metric.merged_duals`), each state's road to answer
    as and its weight (of the prior, and of a turn onto it from a road of more weight)."""

    def __init__(self, graph: RoadGraph, states: DirectedEdges, settings: MetricSettings,
                 lane_offset_m: NDArray[np.float64] | None = None, added: AddedRoads | None = None) -> None:
        self.settings = settings
        chains = lane_chains(graph, states, settings.turn_zone_m, settings.heading_window_m, settings.u_turn_weight,
                             settings.turn_path, settings.wide_zone_m, settings.u_turn_gap_m,
                             settings.wide_share, None if added is None else added.weight)
        self.grid = grid = CellGrid(graph, states, chains, settings.cell_m, settings.heading_window_m, lane_offset_m)
        if added is not None:  # roads added to the map answer as the map's road they stand for, and are less likely
            grid.edge, grid.num_roads = added.origin[grid.state], added.roads
            prior = grid.prior * added.weight[grid.state]
            grid.prior = prior / prior.sum()
        n = grid.num_cells
        p = settings.step_jitter
        split = settings.branches == "equal"
        one = _transitions(grid, settings.cell_m, split)
        two = _transitions(grid, 2.0 * settings.cell_m, split)
        self.forward = (p * sp.identity(n, format="csr") + (1.0 - 2.0 * p) * one + p * two).tocsr().astype(np.float32)
        back = (one if split else _transitions(grid, settings.cell_m)).T.tocsr()  # rows: the cell a backward step starts from; columns: where it came from
        norm = np.asarray(back.sum(axis=1)).ravel()
        self.backward = (sp.diags(1.0 / np.maximum(norm, 1e-12)) @ back).tocsr().astype(np.float32)
        self.forward_cols, self.backward_cols = self.forward.T.tocsr(), self.backward.T.tocsr()
        sigma = np.radians(settings.heading_sigma_deg)
        ramp = grid.turn_ramp
        if settings.bend_spread:  # a bend inside a road is driven as loosely as a turn through a node
            ramp = np.maximum(ramp, grid.bend_ramp(graph, settings.turn_zone_m))
        turning = settings.turn_sigma_share * ramp  # how a vehicle turns varies: the more, the sharper the turn
        self.kappa_obs = (1.0 / (sigma**2 + turning**2)).astype(np.float32)  # von Mises concentration of one observation
        # ``tolerance``: the density's normaliser stays that of a straight road's spread; ``density``: the wider one's
        self.norm_kappa = np.float32(1.0 / sigma**2) if settings.turn_spread == "tolerance" else None
        self.unheading = np.exp(-1j * np.radians(grid.heading)).astype(np.complex64)  # e^{-i h}: a yaw into an offset
        self.direction = np.column_stack([np.cos(np.radians(grid.heading)), np.sin(np.radians(grid.heading))])  # of travel
        drift = float(np.radians(settings.offset_drift_deg) ** 2 * settings.cell_m / 100.0)  # variance per step
        # through a node the offset may jump (each road's map heading errs its own way): spread over the turn chain
        on_turn = grid.chains.second_state[grid.chain] >= 0
        cells_of_chain = np.diff(grid.base)[grid.chain]
        self.drift = (drift + np.where(on_turn, np.radians(settings.node_offset_deg) ** 2 / np.maximum(cells_of_chain, 1), 0.0)).astype(np.float32)
        # off the map the heading is its last value plus the noise of two observations (times offmap_spread), or anything
        self.offmap_kappa = 1.0 / (2.0 * (settings.offmap_spread * sigma) ** 2)
        self.floor_density = settings.floor / TWO_PI
        k = max(1, int(settings.scale_classes))
        self.scales = np.linspace(-settings.scale_error_max, settings.scale_error_max, k) if k > 1 else np.zeros(1)
        spread = settings.scale_error_max / 2.0 if settings.scale_error_max > 0 else 1.0
        prior = np.exp(-0.5 * (self.scales / spread) ** 2)
        self.scale_prior = prior / prior.sum()
        # the groups a split belief holds: the scale classes, then (with lateral_offset_m) a class driven that far
        # left and one that far right of the lane, without scale error, each as likely as the largest scale error
        extra = [-settings.lateral_offset_m, settings.lateral_offset_m] if settings.lateral_offset_m > 0 else []
        self.class_scale = np.concatenate([self.scales, np.zeros(len(extra))])
        self.class_offset_m = np.concatenate([np.zeros(k), extra])
        prior = np.concatenate([self.scale_prior, np.full(len(extra), self.scale_prior[0])])
        self.class_prior = prior / prior.sum()

    def offmap_density(self, turn: NDArray[np.float64]) -> NDArray[np.float64]:
        """Density of a heading change ``turn`` (radians, per step) off the map; NaN (no last heading): uniform."""
        p = self.settings.offmap_turn_prob
        straight = np.exp(self.offmap_kappa * (np.cos(turn) - 1.0)) * math.sqrt(self.offmap_kappa / TWO_PI + 1.0 / TWO_PI**2)
        return np.where(np.isfinite(turn), (1.0 - p) * straight + p / TWO_PI, 1.0 / TWO_PI)

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells
