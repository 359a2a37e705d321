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

The loop runs online (:class:`WindowSearch`: one :class:`Frame` in, one :class:`Step` out) and in batch
(:func:`localize`, over a whole drive). :class:`PlaceLocalizer` is the base of the place localizers of
:mod:`topoloc.localizers` (``place_loop``, ``place_filter``, ``place_odometry``): the interface of
:mod:`topoloc.localizer` on a topometric map.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.localizer import Answer, Localizer, Track

ScoreFn = Callable[[int, NDArray[np.int64]], NDArray[np.float64]]

# Per-frame events of the trace.
ODOMETRY, MATCH, NO_MATCH, RELOC_OK, RELOC_FAIL = "odometry", "match", "no_match", "reloc_ok", "reloc_fail"


@dataclass(frozen=True)
class LocalizeSettings:
    """The loop's settings (``place.localize`` in the config; the paper's values are the schema's defaults)."""

    threshold: float
    window: int
    search_every: int
    lost_frames: int
    reloc_images: int
    reloc_span: int
    sequence_frames: int

    def __post_init__(self) -> None:
        for key in ("window", "search_every", "lost_frames", "reloc_images", "sequence_frames"):
            if int(getattr(self, key)) < 1:
                raise InputError(f"place.localize.{key}", f"must be at least 1, got {getattr(self, key)}")
        if int(self.reloc_span) < 0:
            raise InputError("place.localize.reloc_span", f"must be non-negative, got {self.reloc_span}")

    @classmethod
    def from_conf(cls, loc: dict[str, Any], threshold_key: str = "threshold") -> LocalizeSettings:
        """Settings of the validated ``place.localize`` slice, with the threshold of ``threshold_key``."""
        return cls(float(loc[threshold_key]), int(loc["window"]), int(loc["search_every"]), int(loc["lost_frames"]),
                   int(loc["reloc_images"]), int(loc["reloc_span"]), int(loc["sequence_frames"]))


class Step(NamedTuple):
    """One repeat frame's estimate: vertex, arc length, event, score (the loop: best search score, NaN if none)."""

    vertex: int
    s: float
    event: str
    score: float


@dataclass
class Trace:
    """Per repeat frame: estimated arc length and vertex, event, best score of the search (NaN if none)."""

    s: NDArray[np.float64]
    vertex: NDArray[np.int64]
    event: list[str]
    score: NDArray[np.float64]

    @classmethod
    def of_steps(cls, steps: Sequence[Step]) -> Trace:
        """The trace of successive steps."""
        return cls(np.array([st.s for st in steps], float), np.array([st.vertex for st in steps], np.int64),
                   [st.event for st in steps], np.array([st.score for st in steps], float))

    def count(self, event: str) -> int:
        """Number of frames with ``event``."""
        return sum(e == event for e in self.event)


@dataclass(frozen=True)
class Frame:
    """One repeat frame as a place localizer observes it: ``ds``, the odometry distance driven since the previous
    frame (ignored on the first), and its image as scores against the map's vertices, frame ``index`` of
    ``scorer``. Scores are asked for lazily: the loop scores a window, the filter every vertex."""

    ds: float
    index: int
    scorer: ScoreFn

    def score(self, vertices: NDArray[np.int64]) -> NDArray[np.float64]:
        """Scores of this frame against ``vertices``."""
        return self.scorer(self.index, vertices)

    def row(self) -> NDArray[np.float64]:
        """Scores of this frame against every vertex (the scorer must be a :class:`Scorer`)."""
        return self.scorer.row(self.index)  # type: ignore[attr-defined]


def drive_frames(ds: NDArray[np.float64], scorer: ScoreFn) -> list[Frame]:
    """The frames of a drive with odometry distances ``ds`` (``ds[0]`` is ignored) and images scored by ``scorer``."""
    return [Frame(float(d), t, scorer) for t, d in enumerate(np.asarray(ds, float))]


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


class WindowSearch:
    """The loop of the module docstring, one repeat frame at a time (:meth:`start`, then :meth:`update` per frame;
    the methods of :class:`topoloc.localizer.Filter`)."""

    def __init__(self, vertex_s: NDArray[np.float64], settings: LocalizeSettings) -> None:
        self.vertex_s, self.settings = checked_vertex_s(vertex_s), settings
        self.everything = np.arange(len(self.vertex_s), dtype=np.int64)
        self.start()

    def start(self) -> None:
        """Back at vertex 0 before the first frame."""
        self.t, self.s, self.since_match, self.driven = -1, float(self.vertex_s[0]), 0, 0.0
        # the frames the sequence scores and the relocalization look back on, with the repeat's odometry arc length
        self.recent: deque[tuple[Frame, float]] = deque(maxlen=max(self.settings.sequence_frames, self.settings.reloc_images))
        self.global_best: dict[int, int] = {}  # best vertex of a recent frame against all vertices, by frame number
        self.last: Step | None = None

    def _recent(self, k: int) -> tuple[Frame, float]:
        return self.recent[len(self.recent) - 1 - (self.t - k)]

    def _best_global(self, k: int) -> int:
        if k not in self.global_best:
            self.global_best[k] = int(np.argmax(self._recent(k)[0].score(self.everything)))
        return self.global_best[k]

    def _window_scores(self, window: NDArray[np.int64]) -> NDArray[np.float64]:
        t, vertex_s = self.t, self.vertex_s
        total = np.asarray(self._recent(t)[0].score(window), float)
        earlier = range(t - 1, max(-1, t - self.settings.sequence_frames), -1)
        for k in earlier:
            frame, driven = self._recent(k)
            total = total + np.asarray(frame.score(nearest_vertices(vertex_s, vertex_s[window] - (self.driven - driven))), float)
        return total / (1 + len(earlier))

    def update(self, frame: Frame) -> Step:
        """Take the next repeat frame; return its estimate."""
        settings, vertex_s = self.settings, self.vertex_s
        self.t += 1
        t = self.t
        if t > 0:
            self.s += float(frame.ds)
            self.driven += float(frame.ds)
            self.since_match += 1
        self.recent.append((frame, self.driven))
        for k in [k for k in self.global_best if k <= t - settings.reloc_images]:
            del self.global_best[k]  # never looked at again
        v, event, score = nearest_vertex(vertex_s, self.s), ODOMETRY, float("nan")
        if t % settings.search_every == 0:
            if self.since_match >= settings.lost_frames and t + 1 >= settings.reloc_images:
                best = [self._best_global(k) for k in range(t - settings.reloc_images + 1, t + 1)]
                if max(best) - min(best) <= settings.reloc_span:
                    v, self.s, self.since_match, event = best[-1], float(vertex_s[best[-1]]), 0, RELOC_OK
                else:
                    event = RELOC_FAIL
            else:
                window = np.arange(max(0, v - settings.window), min(len(vertex_s), v + settings.window + 1), dtype=np.int64)
                scores = self._window_scores(window)
                j = int(np.argmax(scores))
                score = float(scores[j])
                if scores[j] > settings.threshold:
                    v, self.s, self.since_match, event = int(window[j]), float(vertex_s[window[j]]), 0, MATCH
                else:
                    event = NO_MATCH
        self.last = Step(v, self.s, event, score)
        return self.last

    def answer(self) -> Step | None:
        """The estimate after the last frame (None before the first)."""
        return self.last


def localize(vertex_s: NDArray[np.float64], ds: NDArray[np.float64], score: ScoreFn, settings: LocalizeSettings) -> Trace:
    """Run the loop of the module docstring over ``len(ds)`` repeat frames (``ds[0]`` is ignored)."""
    search = WindowSearch(vertex_s, settings)
    return Trace.of_steps([search.update(frame) for frame in drive_frames(ds, score)])


class PathIntegration:
    """Odometry alone from vertex 0, one frame at a time: the reference without retrieval (the methods of
    :class:`topoloc.localizer.Filter`)."""

    def __init__(self, vertex_s: NDArray[np.float64]) -> None:
        self.vertex_s = checked_vertex_s(vertex_s)
        self.start()

    def start(self) -> None:
        """Back at vertex 0 before the first frame."""
        self.t, self.driven = -1, 0.0
        self.last: Step | None = None

    def update(self, frame: Frame) -> Step:
        """Take the next repeat frame (only its odometry); return its estimate."""
        self.t += 1
        if self.t > 0:
            self.driven += float(frame.ds)
        s = float(self.vertex_s[0] + self.driven)
        self.last = Step(nearest_vertex(self.vertex_s, s), s, ODOMETRY, float("nan"))
        return self.last

    def answer(self) -> Step | None:
        """The estimate after the last frame (None before the first)."""
        return self.last


def dead_reckoning(vertex_s: NDArray[np.float64], ds: NDArray[np.float64]) -> Trace:
    """Path integration alone from vertex 0 over ``len(ds)`` frames (``ds[0]`` is ignored)."""
    integration = PathIntegration(vertex_s)
    return Trace.of_steps([integration.update(frame) for frame in drive_frames(ds, _no_scores)])


def _no_scores(t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
    raise InputError("scores", "path integration looks at no image")


class Scorer(ABC):
    """Scores of the repeat images (by frame) against the map's vertices, higher where more alike."""

    @abstractmethod
    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        """Frame ``t`` against the vertices ``idx``."""

    @abstractmethod
    def matrix(self) -> NDArray[np.float64]:
        """Every frame against every vertex, (frames, vertices), computed at once."""

    def row(self, t: int) -> NDArray[np.float64]:
        """Frame ``t`` against every vertex: a row of :meth:`matrix`, computed on first use for all frames of the
        drive at once (a recorded drive's frames are all known; one matrix is faster than a row per frame)."""
        if getattr(self, "_matrix", None) is None:
            self._matrix = self.matrix()
        return self._matrix[t]


class MatrixScorer(Scorer):
    """Scores given as a (frames, vertices) matrix."""

    def __init__(self, scores: NDArray[np.float64]) -> None:
        self.scores = scores

    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return self.scores[t, idx]

    def matrix(self) -> NDArray[np.float64]:
        return self.scores


class NetworkScorer(Scorer):
    """Scores of the siamese network: P(same place) of a repeat embedding against vertex embeddings."""

    def __init__(self, model: Any, queries: NDArray[np.float32], vertices: NDArray[np.float32]) -> None:
        self.model, self.queries, self.vertices = model, queries, vertices

    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return np.asarray(self.model.same_place(self.queries[t], self.vertices[idx]), float)

    def matrix(self) -> NDArray[np.float64]:
        return self.model.score_matrix(self.queries, self.vertices)


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


class CorrelationScorer(Scorer):
    """Baseline scores: normalised cross-correlation of downsampled images (in [-1, 1])."""

    def __init__(self, queries: NDArray[np.float32], vertices: NDArray[np.float32]) -> None:
        self.queries, self.vertices = queries, vertices

    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return (self.vertices[idx] @ self.queries[t]).astype(float)

    def matrix(self) -> NDArray[np.float64]:
        return self.queries @ self.vertices.T


class PlaceLocalizer(Localizer):
    """A localizer on a topometric map (teach and repeat): the map is a
    :class:`~topoloc.place.topometric_map.TopometricMap` (its vertex arc lengths ``s`` and positions ``xy``),
    one observation a :class:`Frame`, ``conf`` the validated ``place.localize`` slice, whose ``threshold`` is on
    the scale of the frames' scores. The answer's state is a vertex, ``xy`` its position on the map; the
    batch form's :class:`~topoloc.localizer.Track` holds the :class:`Trace` as ``extra["trace"]``.
    """

    observes = "images"
    #: Row of the ``localize_repeat`` tables, ``{scores}`` standing for the scorer (``siamese network``,
    #: ``raw correlation``). Without ``{scores}`` the localizer looks at no image and runs once per drive.
    row: ClassVar[str] = ""
    #: The same for the names of the stage's metrics (``{scores}``: ``network``, ``correlation``).
    metric: ClassVar[str] = ""

    def setup(self, map: Any, conf: dict[str, Any]) -> None:
        self.vertex_s, self.xy = checked_vertex_s(map.s), np.asarray(map.xy, float)

    def start(self) -> None:
        self._answer, self.last = Answer(-1, 0.0), None

    @abstractmethod
    def estimate(self, frame: Frame) -> Step:
        """The estimate after ``frame`` (of the localizer's :class:`~topoloc.localizer.Filter`)."""

    def confidence(self, step: Step) -> float:
        """The confidence of ``step``'s vertex."""
        return 0.0

    def update(self, observation: Frame) -> Answer:
        self.last = self.estimate(observation)
        self._answer = Answer(self.last.vertex, self.confidence(self.last), tuple(self.xy[self.last.vertex]))
        return self._answer

    def answer(self) -> Answer:
        return self._answer

    def run(self, observations: Sequence[Frame]) -> Track:
        answers, steps = [], []
        for frame in observations:
            answers.append(self.update(frame))
            steps.append(self.last)
        return Track.of_answers(answers, self.path(), trace=Trace.of_steps(steps))
