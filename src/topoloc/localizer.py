"""One interface for every localizer.

A localizer answers, one observation at a time, where the vehicle is:

* :meth:`Localizer.reset` ``(map, conf)`` starts over on a map (a :class:`~topoloc.localization.roadmap.RoadMap`
  for road localizers, a topometric map for place localizers) with the localizer's config slice;
  structures that depend only on the map and the config are built once and kept across resets;
* :meth:`Localizer.update` ``(observation) -> Answer`` takes the next observation (a token, an odometry
  step, an image frame: see :attr:`Localizer.observes`) and returns the new belief's answer;
* :meth:`Localizer.answer` returns the current answer: the state (a road id on a road map, a vertex on a
  topometric map), a map position where the localizer has one, and the confidence;
* :meth:`Localizer.path` returns, after the last update, the consistent sequence of states traced back
  (Viterbi, or the best final hypothesis); localizers without one return their online answers.

An answer also lists its *top places* (:class:`Place`, :attr:`Answer.places`): the most probable states with
their probabilities and positions, where the localizer's filter ranks them (the optional ``top_places(k)`` of
:class:`RankedFilter`); places within ``merge_m`` metres of a more probable one are merged into it
(:func:`merge_places`). The answer is then the top place, and its confidence that place's probability: when two
places explain the drive about equally (a mirror walk), the answer names both and is at most 0.5 sure.

:func:`run_batch` is the batch form: it feeds a whole sequence of observations and collects a
:class:`Track`. Subclasses may override :meth:`Localizer.run` with a faster equivalent (the tests check
that both agree).

Every filter inside a localizer (the metric filter, the token HMM, the beam decoder, the place filters)
follows :class:`Filter`, the same vocabulary without a map: ``start``, ``update``, ``answer``, and ``path``
where it traces one back.

Localizers register themselves by name with :func:`register`; the name is the config key, the CLI
choice and the table row, :attr:`Localizer.label` the label of tables and figures. Every module of the
package :mod:`topoloc.localizers` is imported by :func:`topoloc.registry.registry`, so a new localizer is one module
there (plus its schema entry and its test).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

#: What a localizer observes, one item per update.
OBSERVATIONS = ("tokens", "odometry", "images")
#: What the localizers on a road map observe (a drive's odometry); the others, on a topometric map, observe images.
ROAD_OBSERVATIONS = ("tokens", "odometry")
#: What the place localizers (teach and repeat, on a topometric map) observe: repeat frames.
PLACE_OBSERVATIONS = ("images",)


@dataclass(frozen=True)
class Place:
    """One of the places a filter ranks: a state (a road on a road map), its probability and its best position."""

    state: int
    probability: float
    xy: tuple[float, float] | None = None


def merge_places(states: Sequence[int], probability: Sequence[float], xy: NDArray[np.float64] | None, k: int,
                 merge_m: float = 0.0) -> list[Place]:
    """The ``k`` most probable places of candidate ``states`` (with their ``probability`` and positions ``xy``
    ``(n, 2)``, NaN where none): in order of probability, a candidate within ``merge_m`` metres of a place already
    kept adds its probability to that place (the same place under two states, e.g. two roads at a node);
    most probable first."""
    p = np.asarray(probability, float)
    pos = np.full((len(p), 2), np.nan) if xy is None else np.asarray(xy, float).reshape(-1, 2)
    order = np.argsort(-p, kind="stable")
    return merge_sorted([int(states[i]) for i in order], p[order].tolist(), pos[order, 0].tolist(), pos[order, 1].tolist(),
                        k, merge_m)


def merge_sorted(states: list[int], probability: list[float], x: list[float], y: list[float], k: int,
                 merge_m: float = 0.0) -> list[Place]:
    """:func:`merge_places` of candidates already sorted by decreasing probability, as plain lists (the fast path
    of the filters, called every step)."""
    kept: list[list] = []  # [state, probability, x, y]
    for state, p, px, py in zip(states, probability, x, y):
        if not p > 0:
            break
        if merge_m > 0 and px == px and py == py:  # not NaN
            near = next((place for place in kept if abs(place[2] - px) <= merge_m and abs(place[3] - py) <= merge_m
                         and math.hypot(place[2] - px, place[3] - py) <= merge_m), None)
            if near is not None:
                near[1] += p
                continue
        kept.append([state, p, px, py])
    if len(kept) > 1:
        kept.sort(key=lambda place: -place[1])
    return [Place(state, p, (px, py) if px == px and py == py else None) for state, p, px, py in kept[:k]]


@dataclass(frozen=True)
class Answer:
    """Where the vehicle is after an update.

    ``state``: a road (undirected edge id) on a road map, a vertex on a topometric map; -1 when the
    localizer has no answer. ``xy``: the map position (projected metres) where the localizer has one,
    else None. ``confidence``: the probability the localizer gives its answer. ``places``: the top places,
    most probable first, where the localizer ranks them (the answer is then the first).
    """

    state: int
    confidence: float
    xy: tuple[float, float] | None = None
    places: tuple[Place, ...] = ()

    @classmethod
    def of_places(cls, places: Sequence[Place]) -> Answer:
        """The answer that is the top of ``places`` (no answer when there is none)."""
        if not places:
            return cls(-1, 0.0)
        top = places[0]
        return cls(top.state, top.probability, top.xy, tuple(places))

    def ranked(self) -> tuple[Place, ...]:
        """The top places; for a localizer that ranks none, the answer itself as the one place (none without an answer)."""
        if self.places:
            return self.places
        return (Place(self.state, self.confidence, self.xy),) if self.state >= 0 else ()


@dataclass
class Track:
    """A localizer's answers over a sequence of observations (one entry per update)."""

    state: NDArray[np.int64]
    confidence: NDArray[np.float64]
    xy: NDArray[np.float64]  #: (n, 2), NaN where the localizer gives no position
    path: NDArray[np.int64]  #: the consistent sequence traced back after the last update
    extra: dict[str, Any] = field(default_factory=dict)
    places: list[tuple[Place, ...]] = field(default_factory=list)  #: per update, the top places (:meth:`Answer.ranked`)

    def __len__(self) -> int:
        return len(self.state)

    @classmethod
    def of_answers(cls, answers: Sequence[Answer], path: NDArray[np.int64] | None = None, **extra: Any) -> Track:
        """A track from the answers of successive updates (``path`` defaults to the answers' states)."""
        state = np.array([a.state for a in answers], np.int64)
        xy = np.array([a.xy if a.xy is not None else (np.nan, np.nan) for a in answers], float).reshape(-1, 2)
        return cls(state, np.array([a.confidence for a in answers], float), xy,
                   state.copy() if path is None else np.asarray(path, np.int64), dict(extra), [a.ranked() for a in answers])

    def place_columns(self, k: int) -> dict[str, NDArray]:
        """The top ``k`` places of every update as columns ``place<i>_state``, ``_prob``, ``_x``, ``_y`` (i = 1..k; -1
        and NaN where an update has fewer places); empty when the track holds no places."""
        n = len(self)
        cols: dict[str, NDArray] = {}
        for i in range(k):
            ranked = [p[i] if i < len(p) else None for p in self.places] if len(self.places) == n else [None] * n
            cols[f"place{i + 1}_state"] = np.array([-1 if p is None else p.state for p in ranked], np.int64)
            cols[f"place{i + 1}_prob"] = np.array([np.nan if p is None else p.probability for p in ranked], float)
            for axis, name in enumerate("xy"):
                cols[f"place{i + 1}_{name}"] = np.array([np.nan if p is None or p.xy is None else p.xy[axis] for p in ranked], float)
        return cols


@runtime_checkable
class Filter(Protocol):
    """A recursive filter, one observation at a time (the vocabulary of every filter, as of :class:`Localizer`).

    * ``start()`` forgets every observation: the belief before the first one (multi-start filters take
      which starts);
    * ``update(*observation)`` takes the next observation (motion, then evidence) and returns the new answer;
    * ``answer()`` returns the answer after the last update;
    * ``path()``, where a filter traces one back, returns the consistent sequence of states of the updates
      so far; ``run(observations)``, where a filter has one, is the batch form (``start``, ``update`` each).
    """

    def start(self) -> None:
        """Forget every observation."""

    def update(self, *observation: Any) -> Any:
        """Take the next observation; return the new answer."""

    def answer(self) -> Any:
        """The answer after the last update."""


@runtime_checkable
class RankedFilter(Filter, Protocol):
    """A :class:`Filter` that also ranks the places its belief holds (optional for a filter; the metric filter,
    the token HMM and through it ``rnn_filter`` have it).

    ``top_places(k, merge_m)`` returns after the last update the ``k`` most probable places (:class:`Place`: a
    state, its probability mass and its best position), most probable first, places within ``merge_m``
    metres merged (:func:`merge_places`); the probabilities sum to at most 1 (the rest lies elsewhere, or off
    the map).
    """

    def top_places(self, k: int, merge_m: float = 0.0) -> list[Place]:
        """The ``k`` most probable places after the last update."""


class Localizer(ABC):
    """Base class of all localizers (see the module docstring)."""

    #: Registry name: config key, CLI choice, table row.
    name: ClassVar[str] = ""
    #: Label of tables and figures.
    label: ClassVar[str] = ""
    #: What one observation is: one of :data:`OBSERVATIONS`.
    observes: ClassVar[str] = ""
    #: Whether it needs the trained trajectory RNN (the workflow then trains it first).
    requires_model: ClassVar[bool] = False

    def __init__(self) -> None:
        self._map: Any = None
        self._conf: Any = None

    def reset(self, map: Any, conf: Any) -> None:
        """Start over on ``map`` with ``conf``; map structures are rebuilt only when either changed."""
        if map is not self._map or conf != self._conf:
            self.setup(map, conf)
            self._map, self._conf = map, conf
        self.start()

    def setup(self, map: Any, conf: Any) -> None:
        """Build what depends only on the map and the config (called by :meth:`reset` when they change)."""

    @abstractmethod
    def start(self) -> None:
        """Forget every observation: the belief before the first one."""

    @abstractmethod
    def update(self, observation: Any) -> Answer:
        """Take one observation; return the new answer."""

    @abstractmethod
    def answer(self) -> Answer:
        """The current answer."""

    def path(self) -> NDArray[np.int64] | None:
        """The consistent state sequence traced back after the last update (None: use the online answers)."""
        return None

    def summary(self) -> dict[str, Any]:
        """Facts of the run so far for the stage's statistics (initial hypotheses, restarts, ...)."""
        return {}

    def run(self, observations: Sequence[Any]) -> Track:
        """The batch form: :meth:`update` on every observation in turn (call :meth:`reset` first)."""
        answers = [self.update(obs) for obs in observations]
        return Track.of_answers(answers, self.path())


_REGISTRY: dict[str, type[Localizer]] = {}


def register(cls: type[Localizer]) -> type[Localizer]:
    """Class decorator: make ``cls`` available under ``cls.name``."""
    if not cls.name or not cls.label or cls.observes not in OBSERVATIONS:
        raise TypeError(f"{cls.__name__}: a localizer needs a name, a label and observes in {OBSERVATIONS}")
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise TypeError(f"two localizers are named {cls.name!r}: {_REGISTRY[cls.name].__name__} and {cls.__name__}")
    _REGISTRY[cls.name] = cls
    return cls


def run_batch(localizer: Localizer, map: Any, conf: Any, observations: Sequence[Any]) -> Track:
    """Reset ``localizer`` on ``map`` and run it over ``observations``."""
    localizer.reset(map, conf)
    return localizer.run(observations)
