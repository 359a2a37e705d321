"""Image pairs for the siamese network, labelled by the metric distance of their places (the paper's 2 m rule).

A pair is two places of a :class:`~topoloc.place.images.PlaceSet`, each seen under one condition:

* **positive** (label 1): the places are less than ``positive_m`` (2 m) apart and their headings differ by
  at most ``max_heading_deg`` (the same view; the place itself counts). The two images are always under
  *different* conditions (the paper draws positives across weather and illumination);
* **negative** (label 0): the places are more than ``positive_m`` apart. A share ``hard_share`` are *hard*
  negatives: same heading, ``hard_negative_m[0]``..``hard_negative_m[1]`` apart (the next houses down the
  same street); the rest are drawn from anywhere farther than ``positive_m``. Negatives are also drawn
  across conditions, so the condition of an image says nothing about the label.

Places closer than ``positive_m`` with opposite headings are never paired (neither label fits).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from topoloc.errors import InputError

IGNORE = -100


@dataclass(frozen=True)
class Pairs:
    """Index arrays of pairs: place and condition of each side, and the label (1 same place, 0 different)."""

    place_a: NDArray[np.int64]
    cond_a: NDArray[np.int64]
    place_b: NDArray[np.int64]
    cond_b: NDArray[np.int64]
    label: NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.label)


def heading_difference(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Absolute heading difference in degrees, in [0, 180]."""
    d = np.mod(np.degrees(np.asarray(a) - np.asarray(b)) + 180.0, 360.0) - 180.0
    return np.abs(d)


class PairSampler:
    """Draws pairs among places ``xy`` / ``yaw`` under the condition indices ``conditions``.

    Parameters
    ----------
    xy, yaw
        Ground-truth positions (n, 2) in metres and headings (n,) in radians of the places.
    conditions
        Indices (into the image set's conditions) that pairs may use; at least two.
    positive_m, hard_negative_m, hard_share, max_heading_deg, positive_share
        See the module docstring; ``positive_share`` is the expected share of positives.
    """

    def __init__(self, xy: NDArray[np.float64], yaw: NDArray[np.float64], conditions: list[int], positive_m: float = 2.0,
                 hard_negative_m: tuple[float, float] = (3.0, 30.0), hard_share: float = 0.5,
                 max_heading_deg: float = 30.0, positive_share: float = 0.5) -> None:
        if len(conditions) < 2:
            raise InputError("place.train.conditions", f"pairs across conditions need at least two, got {len(conditions)}")
        lo, hi = float(hard_negative_m[0]), float(hard_negative_m[1])
        if not positive_m < lo < hi:
            raise InputError("place.pairs.hard_negative_m", f"needs positive_m < min < max, got {positive_m}, [{lo}, {hi}]")
        if len(xy) < 2:
            raise InputError("place", "pairs need at least two places")
        self.xy, self.yaw = np.asarray(xy, float), np.asarray(yaw, float)
        self.conditions = np.asarray(conditions, np.int64)
        self.positive_m, self.hard_share, self.positive_share = float(positive_m), float(hard_share), float(positive_share)
        self.max_heading = float(max_heading_deg)
        tree = cKDTree(self.xy)
        self.positives: list[NDArray[np.int64]] = []
        self.hard: list[NDArray[np.int64]] = []
        for i, near in enumerate(tree.query_ball_point(self.xy, hi)):
            near = np.asarray(near, np.int64)
            d = np.hypot(*(self.xy[near] - self.xy[i]).T)
            same_view = heading_difference(self.yaw[near], self.yaw[i]) <= self.max_heading
            self.positives.append(near[(d < self.positive_m) & same_view])
            self.hard.append(near[(d >= lo) & (d <= hi) & same_view])
        self._tree = tree

    def _conditions(self, n: int, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Two different conditions per pair."""
        k = len(self.conditions)
        a = rng.integers(0, k, n)
        b = (a + rng.integers(1, k, n)) % k
        return self.conditions[a], self.conditions[b]

    def _far(self, i: int, rng: np.random.Generator) -> int:
        """A random place farther than ``positive_m`` from place ``i``."""
        for _ in range(100):
            j = int(rng.integers(len(self.xy)))
            if np.hypot(*(self.xy[j] - self.xy[i])) > self.positive_m:
                return j
        raise InputError("place", "all places lie within positive_m of each other: no negatives")

    def sample(self, n: int, rng: np.random.Generator) -> Pairs:
        """``n`` pairs: about ``positive_share`` positives, the rest negatives (hard ones first where available)."""
        anchors = rng.integers(0, len(self.xy), n)
        positive = rng.random(n) < self.positive_share
        hard = rng.random(n) < self.hard_share
        partner = np.empty(n, np.int64)
        for k, i in enumerate(anchors):
            if positive[k]:
                partner[k] = rng.choice(self.positives[i])  # never empty: the place itself
            elif hard[k] and len(self.hard[i]):
                partner[k] = rng.choice(self.hard[i])
            else:
                partner[k] = self._far(int(i), rng)
        cond_a, cond_b = self._conditions(n, rng)
        swap = rng.random(n) < 0.5  # either side may hold the anchor
        place_a = np.where(swap, partner, anchors)
        place_b = np.where(swap, anchors, partner)
        return Pairs(place_a.astype(np.int64), cond_a, place_b.astype(np.int64), cond_b, positive.astype(np.int64))

    def sample_clustered(self, n: int, cluster: int, rng: np.random.Generator) -> Pairs:
        """``n`` positive pairs whose anchors come in groups of ``cluster`` places of one street (hard-negative range).

        Used with :func:`label_matrix`: every anchor against every other pair's partner is a further pair,
        and the anchors of a group are each other's hard negatives.
        """
        cluster = max(1, int(cluster))
        anchors: list[int] = []
        while len(anchors) < n:
            seed = int(rng.integers(len(self.xy)))
            near = self.hard[seed]
            anchors += [seed, *(rng.choice(near, cluster - 1) if len(near) else [])]
        place_a = np.asarray(anchors[:n], np.int64)
        place_b = np.array([rng.choice(self.positives[i]) for i in place_a], np.int64)
        cond_a, cond_b = self._conditions(n, rng)
        return Pairs(place_a, cond_a, place_b, cond_b, np.ones(n, np.int64))

    def label_matrix(self, place_a: NDArray[np.int64], place_b: NDArray[np.int64]) -> NDArray[np.int64]:
        """Labels of all pairs ``(place_a[i], place_b[j])`` by the 2 m rule: 1, 0, or -100 (ignored: the same spot
        with another heading, or exactly ``positive_m`` apart)."""
        d = np.hypot(*(self.xy[place_a][:, None] - self.xy[place_b][None]).transpose(2, 0, 1))
        same_view = heading_difference(self.yaw[place_a][:, None], self.yaw[place_b][None]) <= self.max_heading
        return np.where(d > self.positive_m, 0, np.where((d < self.positive_m) & same_view, 1, IGNORE)).astype(np.int64)


def pair_distances(xy: NDArray[np.float64], pairs: Pairs) -> NDArray[np.float64]:
    """Metric distance of each pair's places."""
    return np.hypot(*(xy[pairs.place_a] - xy[pairs.place_b]).T)
