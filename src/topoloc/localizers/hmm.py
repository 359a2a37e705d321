"""The token HMM baseline (no learning): :class:`topoloc.localization.hmm.CellHMM` as a localizer."""

from __future__ import annotations

from typing import Any

import numpy as np

from topoloc.geometry import straight_token
from topoloc.localization.hmm import CellHMM, HmmParams
from topoloc.localization.roadmap import Observations, RoadLocalizer, RoadMap, token_observations
from topoloc.localizer import Answer, register
from topoloc.motion.poses import Odometry


@register
class HmmBaseline(RoadLocalizer):
    """Forward filter over 5 m cells of directed edges from the tokens; Viterbi path."""

    name, label, observes = "hmm", "HMM baseline", "tokens"

    def setup(self, map: RoadMap, conf: dict[str, Any]) -> None:
        self.set_places(conf)
        params = HmmParams.from_conf(conf["localization"]["hmm"])
        bins = int(conf["encoding"]["angle_bins"])
        lane = map.lane_offsets(self.lane)
        self.hmm = map.cached(("hmm", params, bins, self.lane),
                              lambda: CellHMM(map.graph, map.states, bins, params, lane))
        self.bins = bins

    def observe(self, odometry: Odometry, map: RoadMap, conf: dict[str, Any]) -> Observations:
        return token_observations(odometry, map, conf, int(conf["encoding"]["angle_bins"]))

    def start(self) -> None:
        self.hmm.start()
        self._answer = Answer(-1, 0.0)

    def update(self, observation: int) -> Answer:
        return self._step(int(observation))

    def _step(self, token: int, evidence: np.ndarray | None = None) -> Answer:
        """One token through the filter (with per-cell log-likelihood ``evidence``, if any); the answer: the top place
        of the forward belief, with the other top places."""
        self.hmm.update(token, evidence=evidence)
        self._answer = Answer.of_places(self.hmm.top_places(self.top, self.merge_m))
        return self._answer

    def answer(self) -> Answer:
        return self._answer

    def path(self) -> np.ndarray | None:
        if not self.hmm.back:
            return None
        cells, _ = self.hmm.path()
        return self.hmm.cell_edge[cells]

    def explained(self, items: list[Any]) -> tuple[float, int]:
        """Share of the turn tokens that the map's turn along the Viterbi path matches, and their number."""
        cells, _ = self.hmm.path()
        tokens_array = np.asarray([i[0] if isinstance(i, tuple) else i for i in items], np.int64)  # (token, features)
        return self.hmm.explained_turns(tokens_array, cells), int(np.sum(tokens_array[1:] != straight_token(self.bins)))

    def summary(self) -> dict[str, Any]:
        if not self.hmm.back:
            return {}
        _, restarts = self.hmm.path()
        return {"initial_hypotheses": [int(e) for e in self.hmm.initial], "restarts": int(restarts),
                "log_evidence": float(self.hmm.log_evidence), "cells": int(self.hmm.num_cells)}
