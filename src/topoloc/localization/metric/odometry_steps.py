"""The metric filter's input: the odometry cut into steps of one cell length, forwards or back."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Steps:
    """The odometry cut into steps of ``step_m``: direction (+1 forward, -1 back), yaw (radians) and frame (the
    first frame at or past the step's point)."""

    direction: NDArray[np.int64]
    yaw: NDArray[np.float64]
    frame: NDArray[np.int64]
    driven_m: NDArray[np.float64]  #: absolute distance driven up to the step, metres
    past_m: NDArray[np.float64]  #: signed metres the frame lies beyond the step's point (negative reversing)

    def __len__(self) -> int:
        return len(self.direction)


def odometry_steps(xy: NDArray[np.float64], yaw: NDArray[np.float64], step_m: float) -> Steps:
    """Steps of ``step_m`` metres of the planar odometry ``xy`` (n, 2), ``yaw`` (n,) radians.

    The signed distance of a frame is its displacement along the mean yaw of its two poses (negative
    when reversing); a step is taken each time the signed arc length crosses the next multiple of
    ``step_m`` up or down, with the yaw interpolated there.
    """
    xy = np.asarray(xy, float)
    yaw = np.unwrap(np.asarray(yaw, float))
    if len(xy) < 2:
        return Steps(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    move = np.diff(xy, axis=0)
    mid = 0.5 * (yaw[1:] + yaw[:-1])
    ds = move[:, 0] * np.cos(mid) + move[:, 1] * np.sin(mid)
    s = np.concatenate([[0.0], np.cumsum(ds)])
    driven = np.concatenate([[0.0], np.cumsum(np.abs(ds))])
    direction, yaws, frames, dist, past = [], [], [], [], []
    level = 0
    for k in range(1, len(s)):
        while s[k] >= (level + 1) * step_m or s[k] <= (level - 1) * step_m:
            up = s[k] >= (level + 1) * step_m
            level += 1 if up else -1
            target = level * step_m
            frac = (target - s[k - 1]) / (s[k] - s[k - 1]) if s[k] != s[k - 1] else 1.0
            direction.append(1 if up else -1)
            yaws.append(yaw[k - 1] + frac * (yaw[k] - yaw[k - 1]))
            frames.append(k)
            dist.append(driven[k - 1] + frac * (driven[k] - driven[k - 1]))
            past.append(s[k] - target)
    return Steps(np.asarray(direction, np.int64), np.asarray(yaws), np.asarray(frames, np.int64), np.asarray(dist),
                 np.asarray(past))
