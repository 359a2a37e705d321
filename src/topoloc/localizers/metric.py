"""The registered localizer ``metric``: the adapter of the metric filter (the package
:mod:`topoloc.localization.metric`; on city maps with a coarse phase,
:class:`~topoloc.localization.metric.city_filter.CityFilter`) to :class:`topoloc.localizer.Localizer`."""

from __future__ import annotations

from typing import Any

import numpy as np

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.calibration import LogitCalibration
from topoloc.localization.connectivity import DirectedEdges, directed_edges
from topoloc.localization.metric.cell_grid import lane_offsets
from topoloc.localization.metric.city_filter import CityFilter, coarse_settings, uses_coarse
from topoloc.localization.metric.map_model import AddedRoads, MetricModel, MetricSettings
from topoloc.localization.metric.merged_duals import merge_duals, merged_moves
from topoloc.localization.metric.odometry_steps import odometry_steps
from topoloc.localization.metric.restart import RestartingFilter
from topoloc.localization.roadmap import Observations, RoadLocalizer, RoadMap
from topoloc.localizer import Answer, Place, Track, register
from topoloc.motion.poses import Odometry


def metric_states(map: RoadMap, settings: MetricSettings) -> DirectedEdges:
    """The metric filter's connectivity of ``map``: the map's own, with U-turns where ``settings.u_turns`` allows."""
    if settings.u_turns == map.u_turns:
        return map.states
    return map.cached(("states", settings.u_turns), lambda: directed_edges(map.graph, settings.u_turns, map.max_skip_m))


def metric_map(map: RoadMap, settings: MetricSettings, lane_side: str
               ) -> tuple[RoadGraph, DirectedEdges, np.ndarray, AddedRoads | None]:
    """The graph the metric filter runs on, its states, lane offsets and the roads added to the map (None: none):
    ``map``'s own, or with ``settings.merge_duals_m`` its dual carriageways' merged roads added."""
    if settings.merge_duals_m > 0:
        merged = map.cached(("merged duals", settings.merge_duals_m), lambda: merge_duals(map.graph, settings.merge_duals_m))
        if merged.pairs:
            states = map.cached(("merged duals", settings.merge_duals_m, settings.u_turns),
                                lambda: merged_moves(merged, directed_edges(merged.graph, settings.u_turns, map.max_skip_m)))
            lane = map.cached(("merged duals lane", settings.merge_duals_m, lane_side),
                              lambda: lane_offsets(merged.graph, lane_side))
            weight = np.where(np.repeat(merged.added, 2), settings.merge_duals_weight, 1.0)
            return merged.graph, states, lane, AddedRoads(merged.origin, weight, map.graph.num_edges)
    return map.graph, metric_states(map, settings), map.lane_offsets(lane_side), None


@register
class MetricLocalizer(RoadLocalizer):
    """Positions on directed roads every ``cell_m``, moved by the odometry's distance, weighed by its heading."""

    name, label, observes = "metric", "metric filter", "odometry"

    def setup(self, map: RoadMap, conf: dict[str, Any]) -> None:
        self.set_places(conf)
        settings = MetricSettings.from_conf(conf["localization"]["metric"])
        graph, states, lane, added = metric_map(map, settings, self.lane)
        self.model = model = map.cached(("metric", settings, self.lane),
                                        lambda: MetricModel(graph, states, settings, lane, added))
        coarse = None
        if uses_coarse(settings, model.num_cells):  # a city map: coarse cells while the belief is broad
            wide = coarse_settings(settings)
            coarse = map.cached(("metric", wide, self.lane), lambda: MetricModel(graph, states, wide, lane, added))
        self.coarse_model = coarse
        self.restart = bool(conf["localization"]["metric"]["restart"])
        self.restart_confidence = float(conf["localization"]["metric"]["restart_confidence"])
        self.restart_margin = float(conf["localization"]["metric"]["restart_margin"])
        self.restart_hold_m = float(conf["localization"]["metric"]["restart_hold_m"])
        self.calibrate = LogitCalibration(conf["localization"]["metric"]["confidence_scale"],
                                          conf["localization"]["metric"]["confidence_shift"])
        self.filter = self._bank(1)
        self.past_m = 0.0

    def _bank(self, filters: int) -> CityFilter | RestartingFilter:
        """Filters for ``filters`` starts on this map (with challengers where ``restart`` is on)."""
        if self.restart:
            return RestartingFilter(self.model, self.coarse_model, filters, self.restart_confidence, self.restart_margin,
                                    self.restart_hold_m)
        return CityFilter(self.model, self.coarse_model, filters)

    def observe(self, odometry: Odometry, map: RoadMap, conf: dict[str, Any]) -> Observations:
        steps = odometry_steps(odometry.xy, odometry.yaw, float(conf["localization"]["metric"]["cell_m"]))
        return Observations(list(zip(steps.direction.tolist(), steps.yaw.tolist(), steps.past_m.tolist())), steps.frame)

    def start(self) -> None:
        self.filter.start()
        self.past_m = 0.0

    def update(self, observation: tuple[int, float] | tuple[int, float, float]) -> Answer:
        """One step: its direction and yaw (radians), and optionally the metres driven past it to the frame
        answered at (:attr:`~topoloc.localization.metric.odometry_steps.Steps.past_m`)."""
        direction, yaw, *past = observation
        self.filter.update(int(direction), float(yaw))
        self.past_m = float(past[0]) if past else 0.0
        return self.answer()

    def answer(self) -> Answer:
        """The top place of the belief, with the other top places (``localization.places``), at the frame answered
        at."""
        return Answer.of_places(self._calibrated(self.filter.top_places(self.top, self.merge_m, shift_m=self.past_m)))

    def _calibrated(self, places: list[Place]) -> list[Place]:
        """``places`` with their probabilities recalibrated (``confidence_scale``, ``confidence_shift``)."""
        if self.calibrate.identity:
            return places
        return [Place(p.state, self.calibrate(p.probability), p.xy) for p in places]

    def run_starts(self, odometry: Odometry, map: RoadMap, conf: dict[str, Any],
                   starts: np.ndarray) -> list[tuple[int, Observations, Track]]:
        """All starts at once: one filter per start on the drive's steps (a :class:`CityFilter` of several
        filters), each started at the first step that ends after its start frame."""
        self.reset(map, conf)
        steps = odometry_steps(odometry.xy, odometry.yaw, float(conf["localization"]["metric"]["cell_m"]))
        starts = np.asarray(starts, np.int64)
        first = np.searchsorted(steps.frame, starts, side="right")  # the first step that ends after the start
        keep = first < len(steps)
        starts, first = starts[keep], first[keep]
        bank = self._bank(len(starts))
        answers: list[list[Answer]] = [[] for _ in starts]
        for j in range(len(steps)):
            fresh = np.flatnonzero(first == j)
            if len(fresh):
                bank.start(fresh)
            bank.update(int(steps.direction[j]), float(steps.yaw[j]))
            started = np.flatnonzero(first <= j)
            for b, places in zip(started.tolist(), bank.places(self.top, self.merge_m, started, float(steps.past_m[j]))):
                answers[b].append(Answer.of_places(self._calibrated(places)))
        out = []
        for b, start in enumerate(starts):
            cells = bank.path(b)
            path = np.where(cells >= 0, bank.grid.edge[np.maximum(cells, 0)], -1)
            items = list(zip(steps.direction[first[b]:].tolist(), steps.yaw[first[b]:].tolist()))
            out.append((int(start), Observations(items, steps.frame[first[b]:]), Track.of_answers(answers[b], path)))
        return out

    def path(self) -> np.ndarray | None:
        cells = self.filter.path(0)
        return np.where(cells >= 0, self.filter.grid.edge[np.maximum(cells, 0)], -1) if len(cells) else None
