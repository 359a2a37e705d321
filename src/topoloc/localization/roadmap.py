"""What road localizers share: the map, a drive's odometry, and the observations made from it.

* :class:`RoadMap`: a road graph with its directed-edge connectivity and, for the learned
  localizers, the trained trajectory RNN; localizers keep their map structures in its cache, so
  every start of a multi-start evaluation reuses them.
* a drive's odometry is a :class:`topoloc.motion.poses.Odometry` (positions and yaw, in any frame:
  localizers use only the motion), cut at any frame.
* :class:`Observations`: what a localizer observes of a drive (tokens, odometry steps), each with
  the frame at which it is complete, so that answers can be compared with the truth.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.connectivity import DirectedEdges, directed_edges
from topoloc.localization.metric.cell_grid import lane_offsets
from topoloc.localizer import Localizer, Track
from topoloc.motion.poses import Odometry
from topoloc.segmentation import encode_odometry


class RoadMap:
    """A road graph for road localizers: connectivity (``u_turns``, ``max_skip_m``), model, shared cache."""

    def __init__(self, graph: RoadGraph, u_turns: str = "dead_ends", max_skip_m: float | None = None,
                 model: Any = None) -> None:
        self.graph, self.u_turns, self.max_skip_m, self.model = graph, u_turns, max_skip_m, model
        self.cache: dict[Any, Any] = {}

    @cached_property
    def states(self) -> DirectedEdges:
        """Directed edges and which may follow which."""
        return directed_edges(self.graph, self.u_turns, self.max_skip_m)

    def cached(self, key: Any, build: Any) -> Any:
        """``build()`` once per ``key`` (hashable: a localizer name and its settings)."""
        if key not in self.cache:
            self.cache[key] = build()
        return self.cache[key]

    def lane_offsets(self, side: str) -> NDArray[np.float64]:
        """Per directed edge, where across the road a vehicle keeps
        (:func:`~topoloc.localization.metric.cell_grid.lane_offsets`)."""
        return self.cached(("lane", side), lambda: lane_offsets(self.graph, side))


@dataclass(frozen=True)
class Observations:
    """What a localizer observes of a drive: one item per update, and the frame at which each is complete."""

    items: list[Any]
    frame: NDArray[np.int64]
    extra: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.items)


class RoadLocalizer(Localizer):
    """A localizer on a :class:`RoadMap`; ``conf`` holds the ``localization``, ``segmentation`` and ``encoding`` slices."""

    def set_places(self, conf: dict[str, Any]) -> None:
        """How many top places an answer lists, within how many metres two are one, and where across its road a place
        lies (``localization.places``)."""
        places = conf["localization"]["places"]
        self.top, self.merge_m, self.lane = int(places["top"]), float(places["merge_m"]), str(places["lane"])

    @abstractmethod
    def observe(self, odometry: Odometry, map: RoadMap, conf: dict[str, Any]) -> Observations:
        """What this localizer observes of ``odometry``."""

    def run_starts(self, odometry: Odometry, map: RoadMap, conf: dict[str, Any],
                   starts: NDArray[np.int64]) -> list[tuple[int, Observations, Track]]:
        """The drive from every start frame, nothing before it known: (start, observations with absolute
        frames, track) per start that gives any observation; ``track.extra["summary"]`` holds :meth:`summary` of that
        start. Localizers may run all starts at once."""
        out = []
        for start in np.asarray(starts, np.int64):
            observations = self.observe(odometry.cut(int(start)), map, conf)
            if len(observations) == 0:
                continue
            self.reset(map, conf)
            track = self.run(observations.items)
            track.extra["summary"] = self.summary()  # this start's facts (initial hypotheses, restarts, ...)
            out.append((int(start), Observations(observations.items, observations.frame + int(start), observations.extra), track))
        return out


def token_observations(odometry: Odometry, map: RoadMap, conf: dict[str, Any], bins: int) -> Observations:
    """The drive's Douglas-Peucker tokens (as the ``segment_trajectory`` stage makes them), with their frames.

    ``extra`` holds each token's kind and place and its continuous features
    (:func:`topoloc.segmentation.token_features`, ``features``: ``(T, 3)``).
    """
    track, features = encode_odometry(odometry.xy, odometry.yaw, map.graph.virtual_node_spacing_m, bins, conf)
    return Observations([int(t) for t in track.encoded.tokens], np.asarray(track.frame, np.int64),
                        {"kind": track.kind, "place_m": track.place_m, "features": features})
