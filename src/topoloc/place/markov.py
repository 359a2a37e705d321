"""Markov localization on the topometric map: a Bayes filter over the vertices (beyond the paper).

The paper's loop (:mod:`topoloc.place.topometric_localization`) commits to one vertex per frame: a false match above the
threshold moves the estimate, and a look-alike place inside the window can hold it there. The filter
keeps a belief, a probability per vertex, and per repeat frame ``t``

1. **predicts** with the odometry: the belief moves ``ds[t]`` metres along the vertex chain and blurs by
   ``motion_sigma_m + motion_sigma_rel * ds[t]`` (a Gaussian in metres); a share ``mixing`` is spread
   over all vertices, so a vehicle that is lost (or was never where the belief says) can be found again
   anywhere: this takes the place of global relocalization;
2. **updates** with the image: multiplies the belief by ``floor + score`` of the frame against every
   vertex (``score`` in [0, 1]: the network's probability of "same place", or the baseline's correlation
   clipped to [0, 1]); ``floor`` bounds how much one image can rule out;
3. **estimates** the vertex of highest belief.

The belief starts at vertex 0 (the repeat drive starts where the teach drive did). Because the evidence of
many frames is combined along the motion, one bright false match, a look-alike place and a route that
passes the same place twice do not move the estimate unless the frames that follow agree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from topoloc.errors import InputError
from topoloc.place.topometric_localization import (
    MatrixScorer,
    Step,
    Trace,
    checked_vertex_s,
    drive_frames,
)

FILTER = "filter"  # the event of every frame of a filter trace


@dataclass(frozen=True)
class FilterSettings:
    """The filter's settings (``place.localize.filter`` in the config)."""

    floor: float
    mixing: float
    motion_sigma_m: float
    motion_sigma_rel: float

    def __post_init__(self) -> None:
        if not self.floor > 0:
            raise InputError("place.localize.filter.floor", f"must be positive, got {self.floor}")
        if not 0 <= self.mixing < 1:
            raise InputError("place.localize.filter.mixing", f"must be in [0, 1), got {self.mixing}")
        for key in ("motion_sigma_m", "motion_sigma_rel"):
            if getattr(self, key) < 0:
                raise InputError(f"place.localize.filter.{key}", f"must be non-negative, got {getattr(self, key)}")

    @classmethod
    def from_conf(cls, conf: dict[str, Any]) -> FilterSettings:
        """Settings of the validated ``place.localize.filter`` slice."""
        return cls(float(conf["floor"]), float(conf["mixing"]), float(conf["motion_sigma_m"]), float(conf["motion_sigma_rel"]))


def predict(belief: NDArray[np.float64], vertex_s: NDArray[np.float64], ds: float, settings: FilterSettings,
            spacing: float) -> NDArray[np.float64]:
    """The belief after driving ``ds`` metres: shifted along the chain, blurred, mixed with the uniform."""
    moved = np.interp(vertex_s - ds, vertex_s, belief, left=0.0, right=0.0)
    sigma = (settings.motion_sigma_m + settings.motion_sigma_rel * abs(ds)) / spacing
    if sigma > 0:
        moved = gaussian_filter1d(moved, sigma, mode="constant")
    total = moved.sum()
    moved = moved / total if total > 0 else np.full(len(belief), 1.0 / len(belief))
    return (1.0 - settings.mixing) * moved + settings.mixing / len(belief)


class BayesFilter:
    """The filter of the module docstring, one repeat frame at a time (:meth:`start`, then :meth:`update` per frame;
    the methods of :class:`topoloc.localizer.Filter`)."""

    def __init__(self, vertex_s: NDArray[np.float64], settings: FilterSettings) -> None:
        self.vertex_s, self.settings = checked_vertex_s(vertex_s), settings
        spacing = float(np.median(np.diff(self.vertex_s))) if len(self.vertex_s) > 1 else 1.0
        self.spacing = spacing if spacing > 0 else 1.0
        self.start()

    def start(self) -> None:
        """All belief at vertex 0 before the first frame."""
        self.t = -1
        self.belief = np.zeros(len(self.vertex_s))
        self.belief[0] = 1.0
        self.last: Step | None = None

    def update(self, ds: float, scores: NDArray[np.float64]) -> Step:
        """Take the next frame: ``ds`` metres driven since the last (ignored on the first), ``scores`` against every
        vertex; return the vertex of highest belief with its belief as the score."""
        scores = np.asarray(scores, float)
        if scores.shape != self.belief.shape:
            raise InputError("scores", f"expected {self.belief.shape} (one per vertex), got {scores.shape}")
        self.t += 1
        if self.t > 0:
            self.belief = predict(self.belief, self.vertex_s, float(ds), self.settings, self.spacing)
        self.belief = self.belief * (self.settings.floor + np.clip(scores, 0.0, 1.0))
        self.belief /= self.belief.sum()
        v = int(np.argmax(self.belief))
        self.last = Step(v, float(self.vertex_s[v]), FILTER, float(self.belief[v]))
        return self.last

    def answer(self) -> Step | None:
        """The estimate after the last frame (None before the first)."""
        return self.last


def markov_localize(vertex_s: NDArray[np.float64], ds: NDArray[np.float64], scores: NDArray[np.float64],
                    settings: FilterSettings) -> Trace:
    """Filter ``len(ds)`` repeat frames with ``scores`` (frames, vertices) in [0, 1]; ``ds[0]`` is ignored.

    The trace's ``score`` is the belief of the estimated vertex; ``event`` is ``filter`` throughout.
    """
    bayes = BayesFilter(vertex_s, settings)
    scores = np.asarray(scores, float)
    if scores.shape != (len(ds), len(bayes.vertex_s)):
        raise InputError("scores", f"expected {(len(ds), len(bayes.vertex_s))} (frames, vertices), got {scores.shape}")
    return Trace.of_steps([bayes.update(frame.ds, frame.row()) for frame in drive_frames(ds, MatrixScorer(scores))])
