"""The learned localizers of Zha & Yilmaz: the trajectory RNN's per-token edge probabilities, decoded.

``raw`` takes the RNN's most probable edge at every token; ``strategy1`` and ``strategy2`` keep
hypotheses that are connected on the map (:mod:`topoloc.localization.decoders`). The RNN runs in
windows (config ``localization.rnn``) one token at a time (:class:`topoloc.localization.rnn.OnlineRNN`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from topoloc.errors import InputError
from topoloc.localization.decoders import Beam
from topoloc.localization.rnn import OnlineRNN, check_model
from topoloc.localization.roadmap import Observations, RoadLocalizer, RoadMap, token_observations
from topoloc.localizer import Answer, register
from topoloc.motion.poses import Odometry


class _RnnLocalizer(RoadLocalizer):
    observes, requires_model = "tokens", True

    def setup(self, map: RoadMap, conf: dict[str, Any]) -> None:
        check_model(map, self.name)
        rnn = conf["localization"]["rnn"]
        self.rnn = OnlineRNN(map.model, rnn["window"], rnn["stride"])
        self.bins = int(map.model.hparams.bins)

    def observe(self, odometry: Odometry, map: RoadMap, conf: dict[str, Any]) -> Observations:
        """The drive's tokens; ``(token, features)`` pairs for a model trained with continuous features."""
        obs = token_observations(odometry, map, conf, int(map.model.hparams.bins))
        if not int(map.model.hparams.get("feature_dim", 0)):
            return obs
        items = [(int(t), f) for t, f in zip(obs.items, obs.extra["features"])]
        return Observations(items, obs.frame, obs.extra)

    def start(self) -> None:
        self.rnn.start()
        self._answer = Answer(-1, 0.0)

    def answer(self) -> Answer:
        return self._answer

    def _logp(self, observation: Any) -> np.ndarray:
        token, inputs = observation if isinstance(observation, tuple) else (observation, None)
        if not 0 <= int(token) < self.bins:
            raise InputError("tokens", f"tokens must lie in [0, {self.bins}) for this model, got {token}")
        return self.rnn.update(int(token), inputs)


@register
class RawArgmax(_RnnLocalizer):
    """The RNN's most probable edge at each token (no consistency)."""

    name, label = "raw", "raw (argmax)"

    def update(self, observation: int) -> Answer:
        logp = self._logp(observation)
        edge = int(np.argmax(logp))
        self._answer = Answer(edge, float(np.exp(logp[edge])))
        return self._answer


class _BeamLocalizer(_RnnLocalizer):
    strategy = ""

    def setup(self, map: RoadMap, conf: dict[str, Any]) -> None:
        super().setup(map, conf)
        dec = conf["localization"]["decode"]
        self.beam = Beam(map.states, self.strategy, int(dec["k"]), dec["initial_hypotheses"], dec["score"],
                         int(dec["reseed"]), float(dec["reseed_penalty"]),
                         int(conf["localization"]["evaluate"]["initial_hypotheses"]))

    def start(self) -> None:
        super().start()
        self.beam.start()
        self.steps = 0

    def update(self, observation: int) -> Answer:
        logp = self._logp(observation)
        edge, share = self.beam.update(logp)
        self.steps += 1
        self._answer = Answer(edge, share)
        return self._answer

    def path(self) -> np.ndarray | None:
        return self.beam.path() if self.steps else None

    def summary(self) -> dict[str, Any]:
        if not self.steps:
            return {}
        return {"initial_hypotheses": [int(e) for e in self.beam.initial_edges], "restarts": int(self.beam.restarts)}


@register
class Strategy1(_BeamLocalizer):
    """Strategy 1: every hypothesis expands along the map; the top ``k`` are kept."""

    name, label, strategy = "strategy1", "Strategy 1", "strategy1"


@register
class Strategy2(_BeamLocalizer):
    """Strategy 2: the RNN's top ``k`` edges per step, less those not connected to a surviving hypothesis."""

    name, label, strategy = "strategy2", "Strategy 2", "strategy2"
