"""Stereo visual odometry on rectified KITTI-style image pairs, with OpenCV.

Per frame ``k`` -> ``k + 1``:

1. features: Shi-Tomasi corners (GFTT) on the left image ``k``, spread by a
   minimum distance;
2. stereo depth: each corner is tracked into the right image ``k`` with
   pyramidal KLT; a match must stay on its row (rectified pair, ``|dy| <=
   max_row_error_px``) and have a disparity within the depth range; depth is
   ``f * baseline / disparity``;
3. temporal tracking: the corners with depth are tracked into the left image
   ``k + 1`` with KLT (optionally forward-backward checked: ``fb_error_px`` > 0);
4. motion: PnP with RANSAC (EPnP hypotheses) on the 3-D points of frame ``k``
   and their 2-D positions in frame ``k + 1``, then a Levenberg-Marquardt
   refinement on the inliers (local refinement);
5. a frame with fewer than ``min_inliers`` inliers keeps the previous motion
   (constant-velocity prior) and is flagged; the run goes on.

Poses are camera-0-to-world in KITTI convention, frame 0 at the identity.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from topoloc.errors import InputError
from topoloc.motion.poses import read_calib

log = logging.getLogger(__name__)

_LK = {"winSize": (15, 15), "maxLevel": 3,
       "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)}


@dataclass(frozen=True)
class Motion:
    """``T`` maps points of frame k to frame k + 1 (4x4); ``ok`` False when the prior had to be used."""

    T: NDArray[np.float64]
    inliers: int
    features: int
    ok: bool


def _gray(image: NDArray) -> NDArray[np.uint8]:
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image


def stereo_points(K: NDArray, baseline: float, left: NDArray, right: NDArray, conf: dict[str, Any]) -> tuple[NDArray, NDArray]:
    """Corners of ``left`` (n, 2) and their 3-D points (n, 3) in the left camera frame from the stereo pair."""
    corners = cv2.goodFeaturesToTrack(left, conf["max_features"], conf["quality"], conf["min_distance_px"], blockSize=7)
    if corners is None:
        return np.empty((0, 2), np.float32), np.empty((0, 3))
    pts = corners.reshape(-1, 2).astype(np.float32)
    matched, status, _ = cv2.calcOpticalFlowPyrLK(left, right, pts, None, **_LK)
    matched = matched.reshape(-1, 2)
    disparity = pts[:, 0] - matched[:, 0]
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    depth_lo, depth_hi = f * baseline / conf["max_depth_m"], f * baseline / conf["min_depth_m"]
    good = (status.ravel() == 1) & (np.abs(pts[:, 1] - matched[:, 1]) <= conf["max_row_error_px"]) \
        & (disparity >= depth_lo) & (disparity <= depth_hi)
    pts, disparity = pts[good], disparity[good]
    z = f * baseline / disparity
    xyz = np.column_stack([(pts[:, 0] - cx) * z / f, (pts[:, 1] - cy) * z / K[1, 1], z])
    return pts, xyz


def track(prev: NDArray, nxt: NDArray, pts: NDArray, fb_error_px: float) -> tuple[NDArray, NDArray[np.bool_]]:
    """KLT tracks of ``pts`` from ``prev`` into ``nxt`` and a mask of the forward-backward-consistent ones."""
    if len(pts) == 0:
        return pts, np.zeros(0, bool)
    fwd, st1, _ = cv2.calcOpticalFlowPyrLK(prev, nxt, pts, None, **_LK)
    if fb_error_px <= 0:  # no forward-backward check: RANSAC alone rejects bad tracks (faster)
        return fwd.reshape(-1, 2), st1.ravel() == 1
    back, st2, _ = cv2.calcOpticalFlowPyrLK(nxt, prev, fwd, None, **_LK)
    ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm(back - pts, axis=1) <= fb_error_px)
    return fwd.reshape(-1, 2), ok


def pnp_motion(K: NDArray, xyz: NDArray, uv: NDArray, conf: dict[str, Any]) -> tuple[NDArray | None, int]:
    """4x4 transform of points from the 3-D frame into the camera that sees them at ``uv``; None if it fails."""
    if len(xyz) < max(6, conf["min_inliers"]):
        return None, 0
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(xyz.astype(np.float64), uv.astype(np.float64), K, None,
                                                 iterationsCount=200, reprojectionError=conf["ransac_reprojection_px"],
                                                 confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not ok or inliers is None or len(inliers) < conf["min_inliers"]:
        return None, 0 if inliers is None else len(inliers)
    idx = inliers.ravel()
    rvec, tvec = cv2.solvePnPRefineLM(xyz[idx].astype(np.float64), uv[idx].astype(np.float64), K, None, rvec, tvec)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T, len(idx)


def relative_motion(K: NDArray, baseline: float, left0: NDArray, right0: NDArray, left1: NDArray,
                    conf: dict[str, Any]) -> Motion:
    """Motion from stereo frame 0 to left image 1 (``conf``: ``odometry.stereo``): ``Motion.T`` maps frame-0 points into camera 1."""
    left0, right0, left1 = _gray(left0), _gray(right0), _gray(left1)
    pts, xyz = stereo_points(K, baseline, left0, right0, conf)
    uv, ok = track(left0, left1, pts, conf["fb_error_px"])
    T, inliers = pnp_motion(K, xyz[ok], uv[ok], conf)
    return Motion(T if T is not None else np.eye(4), inliers, len(pts), T is not None)


def list_sequence(sequence: str | Path) -> tuple[list[Path], list[Path], Path]:
    """Left and right image files and calib.txt of a KITTI sequence folder; InputError when inconsistent."""
    root = Path(sequence)
    calib = root / "calib.txt"
    if not calib.is_file():
        raise InputError(calib, "calib.txt not found (a KITTI sequence needs image_0/, image_1/ and calib.txt)")
    lefts = sorted((root / "image_0").glob("*.png"))
    rights = sorted((root / "image_1").glob("*.png"))
    if not lefts:
        raise InputError(root / "image_0", "no left images (*.png)")
    if len(lefts) != len(rights):
        raise InputError(root, f"{len(lefts)} left images in image_0/ but {len(rights)} right images in image_1/")
    if [p.name for p in lefts] != [p.name for p in rights]:
        raise InputError(root, "image_0/ and image_1/ hold different file names")
    return lefts, rights, calib


def _read(path: Path) -> NDArray[np.uint8]:
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise InputError(path, "not a readable image")
    return image


def run_stereo_vo(sequence: str | Path, conf: dict[str, Any]) -> tuple[NDArray, NDArray[np.bool_], dict[str, Any]]:
    """Poses (n, 4, 4), per-frame flags (motion prior used) and run facts of the VO on a KITTI sequence folder.

    ``conf`` is the ``odometry.stereo`` config slice.
    """
    lefts, rights, calib = list_sequence(sequence)
    K, baseline = read_calib(calib)
    poses = np.tile(np.eye(4), (len(lefts), 1, 1))
    flagged = np.zeros(len(lefts), dtype=bool)
    inliers = np.zeros(len(lefts), dtype=int)
    prior = np.eye(4)
    left, right = _read(lefts[0]), _read(rights[0])
    started = time.perf_counter()
    for k in tqdm(range(1, len(lefts)), desc="stereo VO", unit="frame", mininterval=1.0):
        nxt = _read(lefts[k])
        pts, xyz = stereo_points(K, baseline, left, right, conf)
        uv, ok = track(left, nxt, pts, conf["fb_error_px"])
        T, inliers[k] = pnp_motion(K, xyz[ok], uv[ok], conf)
        if T is None:
            T, flagged[k] = prior, True
            log.warning("frame %d: %d inliers of %d features; constant-velocity prior used", k, inliers[k], len(pts))
        prior = T
        poses[k] = poses[k - 1] @ np.linalg.inv(T)
        left, right = nxt, _read(rights[k])
    elapsed = time.perf_counter() - started
    facts = {"vo_fps": (len(lefts) - 1) / elapsed if elapsed > 0 else float("nan"),
             "vo_median_inliers": float(np.median(inliers[1:])) if len(lefts) > 1 else 0.0}
    return poses, flagged, facts
