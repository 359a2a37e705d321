"""Odometry error against ground truth: the KITTI benchmark metric and the absolute trajectory error.

* KITTI (devkit ``evaluate_odometry``): from every 10th frame, for each length
  100, 200, ..., 800 m of driven ground-truth distance, the relative pose error
  ``inv(inv(G_i) G_j) inv(E_i) E_j``; translational error is its translation
  over the length (reported in %), rotational error its angle over the length
  (reported in deg / 100 m); both averaged over all sub-sequences.
* ATE: RMS of position differences after the least-squares rigid (rotation +
  translation, no scale) alignment of the estimated onto the true positions.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

LENGTHS_M = (100, 200, 300, 400, 500, 600, 700, 800)


def kitti_errors(gt: NDArray[np.float64], est: NDArray[np.float64], step: int = 10,
                 lengths: tuple[int, ...] = LENGTHS_M) -> dict[str, float]:
    """``t_err_pct``, ``r_err_deg_per_100m`` and the number of sub-sequences (0: drive shorter than 100 m: NaN errors)."""
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1))])
    t_errs, r_errs = [], []
    inv_gt = np.linalg.inv(gt)
    inv_est = np.linalg.inv(est)
    for first in range(0, len(gt), step):
        for length in lengths:
            last = int(np.searchsorted(dist, dist[first] + length))
            if last >= len(gt):
                continue
            delta_gt = inv_gt[first] @ gt[last]
            delta_est = inv_est[first] @ est[last]
            err = np.linalg.inv(delta_gt) @ delta_est
            t_errs.append(np.linalg.norm(err[:3, 3]) / length)
            cos = np.clip((np.trace(err[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
            r_errs.append(np.arccos(cos) / length)
    if not t_errs:
        return {"t_err_pct": float("nan"), "r_err_deg_per_100m": float("nan"), "kitti_subsequences": 0}
    return {"t_err_pct": float(100.0 * np.mean(t_errs)),
            "r_err_deg_per_100m": float(np.degrees(np.mean(r_errs)) * 100.0),
            "kitti_subsequences": len(t_errs)}


def align_rigid(est: NDArray[np.float64], gt: NDArray[np.float64]) -> NDArray[np.float64]:
    """``est`` points (n, d) after the least-squares rotation + translation onto ``gt`` (Umeyama without scale)."""
    mu_e, mu_g = est.mean(axis=0), gt.mean(axis=0)
    u, _, vt = np.linalg.svd((gt - mu_g).T @ (est - mu_e))
    d = np.ones(est.shape[1])
    d[-1] = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag(d) @ vt
    return (est - mu_e) @ rot.T + mu_g


def ate_rmse(gt_positions: NDArray[np.float64], est_positions: NDArray[np.float64]) -> float:
    """Absolute trajectory error (RMS, metres) after rigid alignment."""
    aligned = align_rigid(est_positions, gt_positions)
    return float(np.sqrt(np.mean(np.sum((aligned - gt_positions) ** 2, axis=1))))


def evaluate(gt: NDArray[np.float64], est: NDArray[np.float64]) -> dict[str, float]:
    """KITTI errors and ATE of estimated poses ``est`` against ``gt`` (both (n, 4, 4))."""
    return {**kitti_errors(gt, est), "ate_m": ate_rmse(gt[:, :3, 3], est[:, :3, 3]),
            "gt_length_m": float(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum())}
