"""The paper's teach-and-repeat loop (Cai & Wan): window search, odometry fallback, global relocalization
(:class:`topoloc.place.topometric_localization.WindowSearch`) as a localizer on the topometric map."""

from __future__ import annotations

from typing import Any

import numpy as np

from topoloc.localizer import register
from topoloc.place.topometric_localization import (
    Frame,
    LocalizeSettings,
    PlaceLocalizer,
    Step,
    WindowSearch,
)


@register
class PlaceLoop(PlaceLocalizer):
    """One vertex per frame: the best window match above the threshold, else path integration; relocalized
    on all vertices after ``lost_frames`` without a match. Confidence: the frame's best window score,
    clipped to [0, 1] (0 on frames without a window search)."""

    name, label, row, metric = "place_loop", "window search (Cai & Wan)", "{scores}", "{scores}"

    def setup(self, map: Any, conf: dict[str, Any]) -> None:
        super().setup(map, conf)
        self.search = WindowSearch(self.vertex_s, LocalizeSettings.from_conf(conf))

    def start(self) -> None:
        super().start()
        self.search.start()

    def estimate(self, frame: Frame) -> Step:
        return self.search.update(frame)

    def confidence(self, step: Step) -> float:
        return 0.0 if np.isnan(step.score) else float(np.clip(step.score, 0.0, 1.0))
