"""Odometry alone on the topometric map (:class:`topoloc.place.topometric_localization.PathIntegration`): the reference of
the teach-and-repeat tables, which looks at no image."""

from __future__ import annotations

from typing import Any

from topoloc.localizer import register
from topoloc.place.topometric_localization import Frame, PathIntegration, PlaceLocalizer, Step


@register
class PlaceOdometry(PlaceLocalizer):
    """Path integration of the repeat's odometry from vertex 0; confidence 0 (no evidence)."""

    name, label, row, metric = "place_odometry", "odometry only", "odometry only", "odometry"

    def setup(self, map: Any, conf: dict[str, Any]) -> None:
        super().setup(map, conf)
        self.integration = PathIntegration(self.vertex_s)

    def start(self) -> None:
        super().start()
        self.integration.start()

    def estimate(self, frame: Frame) -> Step:
        return self.integration.update(frame)
