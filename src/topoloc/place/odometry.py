"""Path integration of noisy odometry (the paper integrates the simulator's velocity with Gaussian noise).

From the ground-truth poses of a drive, the per-frame distance ``ds`` and heading change ``dpsi`` are
corrupted by the noise model of :mod:`topoloc.motion.noise`,

* ``ds' = ds (1 + b) + N(0, (distance_noise ds)^2)``, with a scale error ``b ~ N(0, scale_error^2)``
  drawn once per drive (teach and repeat drives get independent errors, so they drift apart);
* ``dpsi' = dpsi + heading_drift_deg_per_100m ds / 100 + N(0, heading_noise_deg^2)``,

and integrated from the true first pose (the step to frame ``k`` is taken along the heading of frame ``k``).
The keys of ``place.odometry_noise`` are those of every noise setting (:data:`topoloc.motion.noise.NOISE_KEYS`);
here ``scale_error`` is the spread of the per-drive draw.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.motion.noise import NOISE_KEYS, OdometryNoise, integrate_odometry
from topoloc.motion.poses import Odometry


def noisy_odometry(xy: NDArray[np.float64], yaw: NDArray[np.float64], noise: dict[str, Any],
                   rng: np.random.Generator, where: str = "place.odometry_noise") -> tuple[Odometry, float]:
    """The odometry of the ground truth ``xy`` (n, 2) / ``yaw`` (n,) (map frame, from the true first pose)
    through the noise model of the module docstring, and the drawn scale error."""
    missing = [k for k in NOISE_KEYS if k not in noise]
    if missing:
        raise InputError(f"{where}.{missing[0]}", "missing odometry noise setting")
    if any(float(noise[k]) < 0 for k in ("scale_error", "distance_noise", "heading_noise_deg")):
        raise InputError(where, "noise standard deviations must be non-negative")
    xy = np.asarray(xy, float)
    scale = float(rng.normal(0.0, float(noise["scale_error"])))
    model = OdometryNoise(scale, float(noise["distance_noise"]), float(noise["heading_drift_deg_per_100m"]),
                          float(noise["heading_noise_deg"]))
    track = integrate_odometry(xy, yaw, model, rng)
    return Odometry(xy[0] + track.xy, track.yaw, track.ds), scale
