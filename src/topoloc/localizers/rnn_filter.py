"""The learned localizer decoded on the map: the trajectory RNN's per-token road distribution as the evidence
of a filter on the map's connectivity (config ``localization.rnn_filter``).

The filter is the token HMM of :mod:`topoloc.localization.hmm` (cells of directed roads, one token moves
the vehicle one virtual-node spacing along the roads that may follow, the token's turning angle against the
map's): its motion prior keeps the answer on a connected, drivable sequence, and its reset mass lets it
recover. At every token the RNN's log-probability of each road, ``w * max(log p, log floor)``
(``evidence_weight`` ``w``, ``floor``), is added to the log-likelihood of every cell of that road. The RNN's
answer is a posterior given all tokens so far, so it is tempered (``w`` < 1) rather than multiplied in at
full weight every step. The RNN runs in windows of ``window`` tokens every ``stride``
(:class:`topoloc.localization.rnn.OnlineRNN`; ``window: null`` one pass), with the continuous per-token
features when the model was trained with them.

The RNN learnt the map's own walks; where the drive leaves them (a U-turn, a road the map has wrong) its evidence can
make the filter sure of a wrong road. With ``confidence: map_checked`` the filter runs beside it the same HMM
without the RNN's evidence (the map alone), and each place's probability is the mean of the two filters' (the
ranking, hence the answer, stays the RNN filter's): it is sure only where the map alone is nearly sure too.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from topoloc.errors import InputError
from topoloc.localization.hmm import CellHMM, HmmParams
from topoloc.localization.rnn import OnlineRNN, check_model
from topoloc.localization.roadmap import Observations, RoadMap, token_observations
from topoloc.localizer import Answer, Place, register
from topoloc.localizers.hmm import HmmBaseline
from topoloc.motion.poses import Odometry

#: How sure the filter says it is (``localization.rnn_filter.confidence``; module docstring).
CONFIDENCE = ("filter", "map_checked")


@register
class RnnFilter(HmmBaseline):
    """HMM forward filter over cells of directed roads whose evidence is the RNN's road distribution; Viterbi path."""

    name, label, observes, requires_model = "rnn_filter", "RNN + map filter", "tokens", True

    def setup(self, map: RoadMap, conf: dict[str, Any]) -> None:
        check_model(map, self.name)
        self.set_places(conf)
        settings = conf["localization"]["rnn_filter"]
        self.bins = int(map.model.hparams.bins)
        params = HmmParams.from_conf(conf["localization"]["hmm"])
        lane = map.lane_offsets(self.lane)
        self.hmm = map.cached(("hmm", params, self.bins, self.lane),
                              lambda: CellHMM(map.graph, map.states, self.bins, params, lane))
        self.rnn = OnlineRNN(map.model, settings["window"], settings["stride"])
        self.weight = float(settings["evidence_weight"])
        self.log_floor = float(np.log(float(settings["floor"])))
        self.feature_dim = int(map.model.hparams.get("feature_dim", 0))
        if settings["confidence"] not in CONFIDENCE:
            raise InputError("localization.rnn_filter.confidence",
                             f"must be one of {list(CONFIDENCE)}, got {settings['confidence']!r}")
        self.map_checked = settings["confidence"] == "map_checked"

    def observe(self, odometry: Odometry, map: RoadMap, conf: dict[str, Any]) -> Observations:
        """The drive's tokens, each with its continuous features: ``(token, features)``."""
        obs = token_observations(odometry, map, conf, int(map.model.hparams.bins))
        return Observations([(int(t), f) for t, f in zip(obs.items, obs.extra["features"])], obs.frame, obs.extra)

    def start(self) -> None:
        super().start()
        self.rnn.start()
        self.map_alpha = self.hmm.alpha.copy()  # the map alone: the same HMM without the RNN's evidence

    def update(self, observation: Any) -> Answer:
        token, inputs = observation if isinstance(observation, tuple) else (observation, None)
        if not 0 <= int(token) < self.bins:
            raise InputError("tokens", f"tokens must lie in [0, {self.bins}) for this model, got {token}")
        logp = self.rnn.update(int(token), inputs if self.feature_dim else None)
        evidence = self.weight * np.maximum(logp.astype(float), self.log_floor)[self.hmm.cell_edge]
        answer = self._step(int(token), evidence)
        if not self.map_checked:
            return answer
        self.map_alpha, _ = self.hmm.forward(self.map_alpha, int(token))
        self._answer = Answer.of_places(self._map_checked(answer.places))
        return self._answer

    def _map_checked(self, places: tuple[Place, ...]) -> list[Place]:
        """``places`` with each probability the mean of the filter's and the map alone's: its mass on the
        same place (merged alike), or on the place's road where the map alone does not rank it."""
        alone = {p.state: p.probability for p in self.hmm.top_places(self.top, self.merge_m, self.map_alpha)}
        road = np.bincount(self.hmm.cell_edge, weights=self.map_alpha, minlength=self.hmm.states.num_edges)
        return [Place(p.state, 0.5 * float(p.probability + alone.get(p.state, road[p.state])), p.xy) for p in places]
