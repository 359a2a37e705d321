"""Localization in closed loop: every step, the map vertex the vehicle is at and how sure of it.

:class:`GroundTruth` reads it off the vehicle's true progress along the lane; :class:`PlaceLocalization` runs a
place localizer of the registry (:mod:`topoloc.localizers`: ``place_loop``, ``place_filter``, ``place_odometry``)
on the step's image (its place window: the place images' camera), scored by the retrieval network against the map's
embeddings (:class:`OnlineScorer`), and on the odometry distance (the true distance with the noise model of
``place.odometry_noise``: a scale error per drive and white noise, drawn by
:func:`topoloc.drive.episodes.run_episode`).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.simulator import Simulator
from topoloc.errors import InputError
from topoloc.localizer import Localizer
from topoloc.place.topometric_localization import Frame, Scorer
from topoloc.place.topometric_map import TopometricMap


class OnlineScorer(Scorer):
    """Retrieval scores of the images seen so far (embedded one per step) against the map's vertices."""

    def __init__(self, model: Any, vertices: NDArray[np.float32]) -> None:
        self.model, self.vertices, self.queries = model, vertices, []

    def add(self, image: NDArray[np.uint8]) -> int:
        """Embed the next image; its frame index."""
        self.queries.append(self.model.embed(image[None])[0])
        return len(self.queries) - 1

    def __call__(self, t: int, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        return np.asarray(self.model.same_place(self.queries[t], self.vertices[idx]), float)

    def matrix(self) -> NDArray[np.float64]:
        return self.model.score_matrix(np.stack(self.queries), self.vertices)

    def row(self, t: int) -> NDArray[np.float64]:
        return np.asarray(self.model.score_matrix(self.queries[t][None], self.vertices)[0], float)


class Localization(Protocol):
    """Where the vehicle is on the map, one step at a time."""

    name: str

    def start(self, rng: np.random.Generator) -> None: ...

    def update(self, image: NDArray[np.uint8], ds: float, sim: Simulator) -> tuple[int, float]:
        """The vertex after this step and its confidence."""
        ...


class GroundTruth:
    """The vertex at the vehicle's true progress along the lane (always sure)."""

    name = "ground_truth"

    def __init__(self, lane_s: NDArray[np.float64]) -> None:
        self.lane_s = lane_s

    def start(self, rng: np.random.Generator) -> None:
        """Nothing to forget."""

    def update(self, image: NDArray[np.uint8], ds: float, sim: Simulator) -> tuple[int, float]:
        i = int(np.clip(np.searchsorted(self.lane_s, sim.s), 0, len(self.lane_s) - 1))
        if i > 0 and sim.s - self.lane_s[i - 1] < self.lane_s[i] - sim.s:
            i -= 1
        return i, 1.0


class PlaceLocalization:
    """A place localizer of the registry on the map, fed the ``window`` (rows, columns) of the step's image that is the
    place images' camera (:func:`topoloc.drive.camera.place_window`) and the odometry distance."""

    def __init__(self, localizer: Localizer, topo: TopometricMap, model: Any, conf: dict[str, Any],
                 window: tuple[slice, slice]) -> None:
        if model.hparams.embedding_dim != topo.embedding.shape[1]:
            raise InputError("map", f"the topometric map holds {topo.embedding.shape[1]}-d embeddings; the retrieval "
                             f"model gives {model.hparams.embedding_dim}-d ones (rebuild the map with this model)")
        self.localizer, self.topo, self.model, self.conf, self.window = localizer, topo, model, conf, window
        self.name = localizer.name

    def start(self, rng: np.random.Generator) -> None:
        self.localizer.reset(self.topo, self.conf)
        self.scorer = OnlineScorer(self.model, self.topo.embedding)

    def update(self, image: NDArray[np.uint8], ds: float, sim: Simulator) -> tuple[int, float]:
        t = self.scorer.add(image[self.window])
        answer = self.localizer.update(Frame(float(ds), t, self.scorer))
        return int(answer.state), float(answer.confidence)
