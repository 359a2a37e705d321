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
(``place.odometry_noise``: the scale error drawn per drive from ``N(0, scale_error^2)``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from topoloc.motion.poses import Odometry

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
