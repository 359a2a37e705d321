"""Topometric localization of a repeat drive on the teach map (Cai & Wan, Sec. 3.5, the Topo-LP procedure).

The estimate is an arc length ``s`` along the map's vertex chain (the metres of the teach drive's path
integration, :attr:`~topoloc.place.topometric_map.TopometricMap.s`) and the vertex nearest to it. The drive
starts at vertex 0 (teach and repeat start at the same place). Per repeat frame ``t``:

1. **path integration**: ``s += ds[t]``, the repeat's odometry distance since frame ``t - 1``;
2. if the last accepted match is ``lost_frames`` (paper: 30) frames or more ago and ``reloc_images``
   (paper: 5) frames exist, **global relocalization** on a search frame: each of the last ``reloc_images``
   frames is matched independently against *all* vertices (best score); when the spread (max - min) of
   their best vertices is at most ``reloc_span`` (paper: 30 vertices) the estimate jumps to the best
   vertex of the current frame, else it keeps the integrated value and tries again on the next search frame;
3. otherwise, on a **search frame** (every ``search_every`` frames: the fixed rate), **window search**: the
   current image is scored against the vertices within ``window`` vertices of the estimate; when the best
   score exceeds ``threshold`` (paper: 0.8) the estimate jumps to that vertex (the retrieved pose), else
   the integrated value stands.

Beyond the paper, ``sequence_frames`` > 1 scores a window candidate by a short sequence instead of one image
(as SeqSLAM does): the mean score of frames ``t, t-1, ..., t-sequence_frames+1`` against the vertices that
the repeat's odometry puts behind the candidate (at its arc length minus the distance driven since that
frame). One bright false match rarely lines up with its neighbours; the true vertex does. Relocalization
is unchanged. ``sequence_frames: 1`` is the paper's single-image search.

A *scorer* maps (frame, vertex indices) to scores; the network (probability of "same place") and the
raw-correlation baseline are both scorers, and so is the hand-made one of the tests. The Bayes filter of
:mod:`topoloc.place.markov` is the other way to localize with the same scores.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError

ScoreFn = Callable[[int, NDArray[np.int64]], NDArray[np.float64]]

# Per-frame events of the trace.
ODOMETRY, MATCH, NO_MATCH, RELOC_OK, RELOC_FAIL = "odometry", "match", "no_match", "reloc_ok", "reloc_fail"


@dataclass(frozen=True)
class LocalizeSettings:
    """The loop's settings (``place.localize`` in the config); defaults are the paper's where it gives them."""

    threshold: float = 0.8
    window: int = 15
    search_every: int = 1
    lost_frames: int = 30
    reloc_images: int = 5
    reloc_span: int = 30
    sequence_frames: int = 1

    def __post_init__(self) -> None:
        for key in ("window", "search_every", "lost_frames", "reloc_images", "sequence_frames"):
            if int(getattr(self, key)) < 1:
                raise InputError(f"place.localize.{key}", f"must be at least 1, got {getattr(self, key)}")
        if int(self.reloc_span) < 0:
            raise InputError("place.localize.reloc_span", f"must be non-negative, got {self.reloc_span}")


@dataclass
class Trace:
    """Per repeat frame: estimated arc length and vertex, event, best score of the search (NaN if none)."""

    s: NDArray[np.float64]
    vertex: NDArray[np.int64]
    event: list[str]
    score: NDArray[np.float64]
    global_best: dict[int, int] = field(default_factory=dict)

    def count(self, event: str) -> int:
        """Number of frames with ``event``."""
        return sum(e == event for e in self.event)


def nearest_vertex(vertex_s: NDArray[np.float64], s: float) -> int:
    """Index of the vertex whose arc length is nearest to ``s`` (``vertex_s`` non-decreasing)."""
    i = int(np.searchsorted(vertex_s, s))
    if i <= 0:
        return 0
    if i >= len(vertex_s):
        return len(vertex_s) - 1
    return i if vertex_s[i] - s < s - vertex_s[i - 1] else i - 1


def nearest_vertices(vertex_s: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray[np.int64]:
    """:func:`nearest_vertex` of every arc length in ``s``."""
    i = np.clip(np.searchsorted(vertex_s, s), 1, max(1, len(vertex_s) - 1))
    if len(vertex_s) == 1:
        return np.zeros(len(s), np.int64)
    before = s - vertex_s[i - 1] <= vertex_s[i] - s
    return np.where(before, i - 1, i).astype(np.int64)


def checked_vertex_s(vertex_s: NDArray[np.float64]) -> NDArray[np.float64]:
    """The vertices' arc lengths as floats; InputError unless there are some and they do not decrease."""
    vertex_s = np.asarray(vertex_s, float)
    if len(vertex_s) == 0:
        raise InputError("map", "the topometric map has no vertices")
    if np.any(np.diff(vertex_s) < 0):
        raise InputError("map", "vertex arc lengths must be non-decreasing")
    return vertex_s


def localize(vertex_s: NDArray[np.float64], ds: NDArray[np.float64], score: ScoreFn,
             settings: LocalizeSettings = LocalizeSettings()) -> Trace:
    """Run the loop of the module docstring over ``len(ds)`` repeat frames (``ds[0]`` is ignored)."""
    vertex_s = checked_vertex_s(vertex_s)
    n, m = len(ds), len(vertex_s)
    everything = np.arange(m, dtype=np.int64)
    driven = np.concatenate([[0.0], np.cumsum(np.asarray(ds, float)[1:])])  # the repeat's odometry arc length
    trace = Trace(np.zeros(n), np.zeros(n, np.int64), [], np.full(n, np.nan))
    s = float(vertex_s[0])
    since_match = 0

    def best_global(k: int) -> int:
        if k not in trace.global_best:
            trace.global_best[k] = int(np.argmax(score(k, everything)))
        return trace.global_best[k]

    def window_scores(t: int, window: NDArray[np.int64]) -> NDArray[np.float64]:
        total = np.asarray(score(t, window), float)
        frames = range(t - 1, max(-1, t - settings.sequence_frames), -1)
        for k in frames:
            total = total + np.asarray(score(k, nearest_vertices(vertex_s, vertex_s[window] - (driven[t] - driven[k]))), float)
        return total / (1 + len(frames))

    for t in range(n):
        if t > 0:
            s += float(ds[t])
            since_match += 1
        v = nearest_vertex(vertex_s, s)
        event = ODOMETRY
        if t % settings.search_every == 0:
            if since_match >= settings.lost_frames and t + 1 >= settings.reloc_images:
                best = [best_global(k) for k in range(t - settings.reloc_images + 1, t + 1)]
                if max(best) - min(best) <= settings.reloc_span:
                    v, s, since_match, event = best[-1], float(vertex_s[best[-1]]), 0, RELOC_OK
                else:
                    event = RELOC_FAIL
            else:
                window = np.arange(max(0, v - settings.window), min(m, v + settings.window + 1), dtype=np.int64)
                scores = window_scores(t, window)
                j = int(np.argmax(scores))
                trace.score[t] = scores[j]
                if scores[j] > settings.threshold:
                    v, s, since_match, event = int(window[j]), float(vertex_s[window[j]]), 0, MATCH
                else:
                    event = NO_MATCH
        trace.s[t], trace.vertex[t] = s, v
        trace.event.append(event)
    return trace


class NetworkScorer:
    """Scores of the siamese network: P(same place) of a repeat embedding against vertex embeddings."""

    def __init__(self, model: object, queries: NDArray[np.float32], vertices: NDArray[np.float32]) -> None:
        self.model, self.queries, self.vertices = model, queries, vertices

    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return np.asarray(self.model.same_place(self.queries[t], self.vertices[idx]), float)


def correlation_descriptors(images: NDArray[np.uint8], size: tuple[int, int]) -> NDArray[np.float32]:
    """Raw-image descriptors: grey, downsampled to ``size`` (width, height), zero mean, unit norm."""
    import cv2

    out = np.empty((len(images), size[0] * size[1]), np.float32)
    for k, image in enumerate(images):
        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.shape[-1] == 3 else image[..., 0]
        small = cv2.resize(grey, tuple(int(v) for v in size), interpolation=cv2.INTER_AREA).astype(np.float32).ravel()
        small -= small.mean()
        out[k] = small / max(float(np.linalg.norm(small)), 1e-6)
    return out


class CorrelationScorer:
    """Baseline scores: normalised cross-correlation of downsampled images (in [-1, 1])."""

    def __init__(self, queries: NDArray[np.float32], vertices: NDArray[np.float32]) -> None:
        self.queries, self.vertices = queries, vertices

    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return (self.vertices[idx] @ self.queries[t]).astype(float)
