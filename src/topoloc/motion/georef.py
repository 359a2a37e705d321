"""Georeferencing: place a local (x, z) odometry track on the map (x east, y north, metres).

A georeference is a 2-D rigid transform ``map = R(theta) @ local + t`` (no
scale). It comes either from an origin (lat, lon, heading clockwise from
north of the optical axis at frame 0) or from a least-squares fit of the track
onto per-frame GPS positions projected to the map's CRS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyproj
from numpy.typing import NDArray


@dataclass(frozen=True)
class Georeference:
    """``map = R @ local + t``; ``theta`` counter-clockwise in radians; ``rms_m`` of the fit (0 from an origin)."""

    theta: float
    t: NDArray[np.float64]
    rms_m: float = 0.0

    @property
    def rotation(self) -> NDArray[np.float64]:
        c, s = np.cos(self.theta), np.sin(self.theta)
        return np.array([[c, -s], [s, c]])

    def apply(self, local: NDArray[np.float64]) -> NDArray[np.float64]:
        """Map coordinates of local ``(n, 2)`` points."""
        return np.asarray(local, float) @ self.rotation.T + self.t

    def heading_deg(self, local_yaw: float) -> float:
        """Heading clockwise from north of a local direction (radians from +x)."""
        ccw_from_east = local_yaw + self.theta
        return float(np.mod(90.0 - np.degrees(ccw_from_east), 360.0))

    def to_dict(self, local_yaw0: float) -> dict[str, float]:
        return {"rotation_deg": float(np.degrees(self.theta)), "tx": float(self.t[0]), "ty": float(self.t[1]),
                "rms_m": float(self.rms_m), "heading0_deg": self.heading_deg(local_yaw0)}


def to_map(crs: str, lat: NDArray[np.float64] | float, lon: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """Project WGS84 lat/lon to the map CRS: ``(n, 2)`` (or ``(2,)``) x, y."""
    transformer = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    x, y = transformer.transform(lon, lat)
    return np.column_stack([x, y]) if np.ndim(x) else np.array([x, y])


def from_origin(origin_xy: NDArray[np.float64], heading_deg: float, local_xy0: NDArray[np.float64], local_yaw0: float) -> Georeference:
    """The transform that puts local point ``local_xy0`` (optical axis yaw ``local_yaw0``) at ``origin_xy``, heading ``heading_deg``."""
    target = np.radians(90.0 - heading_deg)  # counter-clockwise from east
    theta = float(np.mod(target - local_yaw0 + np.pi, 2 * np.pi) - np.pi)
    ref = Georeference(theta, np.zeros(2))
    return Georeference(theta, np.asarray(origin_xy, float) - ref.apply(np.asarray(local_xy0)[None])[0])


def fit_rigid(local: NDArray[np.float64], target: NDArray[np.float64]) -> Georeference:
    """Least-squares rotation + translation (Kabsch, no reflection, no scale) of ``local`` onto ``target``."""
    local = np.asarray(local, float)
    target = np.asarray(target, float)
    mu_l, mu_t = local.mean(axis=0), target.mean(axis=0)
    cov = (target - mu_t).T @ (local - mu_l)
    theta = float(np.arctan2(cov[1, 0] - cov[0, 1], cov[0, 0] + cov[1, 1]))
    ref = Georeference(theta, np.zeros(2))
    t = mu_t - ref.rotation @ mu_l
    fitted = Georeference(theta, t)
    rms = float(np.sqrt(np.mean(np.sum((fitted.apply(local) - target) ** 2, axis=1))))
    return Georeference(theta, t, rms)


def grid_heading_deg(crs: str, lat: float, lon: float, heading_true_deg: float) -> float:
    """A heading clockwise from true north, as a heading clockwise from the CRS's grid north (meridian convergence)."""
    north = to_map(crs, np.array([lat, lat + 1e-4]), np.array([lon, lon]))
    d = north[1] - north[0]
    return float(np.mod(heading_true_deg + np.degrees(np.arctan2(d[0], d[1])), 360.0))
