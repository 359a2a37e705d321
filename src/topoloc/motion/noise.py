"""The odometry noise model: noisy per-frame increments of a true drive, integrated into an odometry track.

From the true positions ``xy`` and headings ``yaw`` of a drive, the per-frame distance ``ds`` (signed:
negative on a stretch driven backwards) and heading change ``dpsi`` are corrupted as

* ``ds' = ds (1 + scale_error) + N(0, (distance_noise |ds|)^2)`` (a constant scale error plus white
  noise proportional to the step),
* ``dpsi' = dpsi + heading_drift_deg_per_100m |ds| / 100 + N(0, heading_noise_deg^2)`` (a constant
  gyro-like drift per distance plus white noise per moving frame; a standing vehicle gets none),

and integrated from the true first pose: the step from frame ``k`` to ``k + 1`` is taken along the
heading of frame ``k + 1``, as the truth does. The random draws are, in this order, the distance noise
of every step, then the heading noise of every step.

Every noise setting of the config has the keys of :data:`NOISE_KEYS`. Users:
:func:`topoloc.odometry.simulate.simulate_drive` (``odometry.simulated.noise``),
:func:`topoloc.odometry.simulate.simulate_pattern_drive` and :mod:`topoloc.trajectory.drives` (parameters
drawn per drive from ranges, ``dataset.simulated.noise``), :mod:`topoloc.place.odometry`
(``place.odometry_noise``: the scale error drawn per drive from ``N(0, scale_error^2)``), :func:`noisy_poses`
(``odometry.drives.<drive>.noise``: a real drive's ground-truth poses made a noisy odometry).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from topoloc.motion.poses import Odometry, planar_track

NOISE_KEYS = ("scale_error", "distance_noise", "heading_drift_deg_per_100m", "heading_noise_deg")


@dataclass(frozen=True)
class OdometryNoise:
    """Parameters of the noise model (see the module docstring)."""

    scale_error: float
    distance_noise: float
    heading_drift_deg_per_100m: float
    heading_noise_deg: float

    @classmethod
    def from_dict(cls, noise: Mapping[str, float]) -> OdometryNoise:
        """From a mapping with the keys of :data:`NOISE_KEYS` (a config slice or drawn parameters)."""
        return cls(*(float(noise[key]) for key in NOISE_KEYS))


def integrate_odometry(xy: ArrayLike, yaw: ArrayLike, noise: OdometryNoise, rng: np.random.Generator,
                       sign: ArrayLike | None = None) -> Odometry:
    """Corrupt the true increments of ``xy`` (n, 2) / ``yaw`` (n,) and integrate them (module docstring).

    The odometry's positions are relative to the first frame (``xy[0] = 0``, axes of the truth), its headings
    start at the true first heading, and ``ds`` holds the noisy distance of every step (``ds[0] = 0``).

    ``sign`` (n - 1,): +1 for a step driven forwards, -1 backwards (default: all forwards).
    """
    xy, yaw = np.asarray(xy, float), np.asarray(yaw, float)
    ds = np.hypot(*np.diff(xy, axis=0).T)
    if sign is not None:
        ds = ds * np.asarray(sign, float)
    dpsi = np.diff(np.unwrap(yaw))
    ds_est = ds * (1.0 + noise.scale_error) + rng.standard_normal(len(ds)) * noise.distance_noise * np.abs(ds)
    dpsi_est = (dpsi + np.radians(noise.heading_drift_deg_per_100m) / 100.0 * np.abs(ds)
                + np.radians(noise.heading_noise_deg) * rng.standard_normal(len(ds)) * (np.abs(ds) > 0))
    est_yaw = yaw[0] + np.concatenate([[0.0], np.cumsum(dpsi_est)])
    moves = ds_est[:, None] * np.column_stack([np.cos(est_yaw[1:]), np.sin(est_yaw[1:])])
    return Odometry(np.concatenate([np.zeros((1, 2)), np.cumsum(moves, axis=0)]), est_yaw, np.concatenate([[0.0], ds_est]))


def noisy_poses(poses: ArrayLike, noise: OdometryNoise, rng: np.random.Generator) -> np.ndarray:
    """KITTI camera poses ``(n, 4, 4)`` (say a drive's ground truth) made an odometry with ``noise``.

    The ground-plane track (x, z) and its direction of travel are corrupted and integrated by
    :func:`integrate_odometry` from the first pose; each camera keeps its height, pitch and roll and turns about
    the vertical by the heading error of its frame. Without noise the poses come back unchanged.
    """
    poses = np.asarray(poses, float)
    xy = planar_track(poses)
    step = np.diff(xy, axis=0)
    moving = np.hypot(*step.T) > 1e-9
    travel = np.full(len(xy), np.nan)
    travel[1:][moving] = np.arctan2(step[moving, 1], step[moving, 0])  # frame k + 1: the direction of step k
    known = np.flatnonzero(np.isfinite(travel))
    if len(known) == 0:
        return poses.copy()
    travel[0] = travel[known[0]]
    travel = travel[np.maximum.accumulate(np.where(np.isfinite(travel), np.arange(len(travel)), 0))]  # standing: the last
    travel = np.unwrap(travel)
    odometry = integrate_odometry(xy, travel, noise, rng)
    error = odometry.yaw - travel  # the heading error of every frame
    out = poses.copy()
    c, s = np.cos(-error), np.sin(-error)  # about the camera's down axis: the planar yaw grows by the error
    turn = np.zeros((len(xy), 3, 3))
    turn[:, 0, 0], turn[:, 0, 2], turn[:, 1, 1], turn[:, 2, 0], turn[:, 2, 2] = c, s, 1.0, -s, c
    out[:, :3, :3] = turn @ poses[:, :3, :3]
    out[:, 0, 3], out[:, 2, 3] = odometry.xy[:, 0] + xy[0, 0], odometry.xy[:, 1] + xy[0, 1]
    return out
