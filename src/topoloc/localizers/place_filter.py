"""Markov localization on the topometric map: the Bayes filter over the vertices
(:class:`topoloc.place.markov.BayesFilter`) as a localizer."""

from __future__ import annotations

from typing import Any

from topoloc.localizer import register
from topoloc.place.markov import BayesFilter, FilterSettings
from topoloc.place.topometric_localization import Frame, PlaceLocalizer, Step


@register
class PlaceFilter(PlaceLocalizer):
    """A belief over the vertices, moved by the odometry and weighed by the frame's scores against every vertex;
    the answer is the vertex of highest belief, its belief the confidence."""

    name, label, row, metric = "place_filter", "Bayes filter over the vertices", "{scores} + filter", "{scores}_filter"

    def setup(self, map: Any, conf: dict[str, Any]) -> None:
        super().setup(map, conf)
        self.bayes = BayesFilter(self.vertex_s, FilterSettings.from_conf(conf["filter"]))

    def start(self) -> None:
        super().start()
        self.bayes.start()

    def estimate(self, frame: Frame) -> Step:
        return self.bayes.update(frame.ds, frame.row())

    def confidence(self, step: Step) -> float:
        return step.score
