"""Stereo VO on rendered stereo sequences with known motion (topoloc.odometry.synthetic), on the real KITTI pair,
and its input errors. Speed figures: benchmarks/bench_odometry.py."""

import cv2
import numpy as np
import pytest

from tests.conftest import make_config
from topoloc.errors import InputError
from topoloc.motion.poses import planar_track, read_calib
from topoloc.odometry.stereo_vo import list_sequence, relative_motion, run_stereo_vo
from topoloc.odometry.synthetic import (
    BASELINE,
    CALIB,
    H,
    K,
    W,
    known_path,
    stereo_pair,
    write_sequence,
)

STEREO = make_config()["odometry"]["stereo"]


def test_one_step_known_motion():
    poses = known_path(2, step=1.2)
    left0, right0 = stereo_pair(poses[0])
    left1, _ = stereo_pair(poses[1])
    motion = relative_motion(K, BASELINE, left0, right0, left1, STEREO)
    assert motion.ok and motion.inliers > 100
    moved = np.linalg.inv(motion.T)[:3, 3]
    assert np.linalg.norm(moved - (np.linalg.inv(poses[0]) @ poses[1])[:3, 3]) < 0.02 * 1.2


@pytest.mark.slow
def test_sequence_recovers_path(tmp_path):
    gt = known_path(30)
    root = write_sequence(tmp_path / "seq", gt)
    est, flagged, facts = run_stereo_vo(root, STEREO)
    assert not flagged.any()
    length = np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum()
    end_error = np.linalg.norm(est[-1, :3, 3] - gt[-1, :3, 3])
    steps_est = np.linalg.norm(np.diff(est[:, :3, 3], axis=0), axis=1)
    assert end_error / length <= 0.02
    assert np.abs(steps_est.sum() - length) / length <= 0.02
    assert np.max(np.abs(planar_track(est) - planar_track(gt))) <= 0.02 * length
    print(f"synthetic stereo VO: end error {100 * end_error / length:.3f} % of {length:.0f} m, {facts['vo_fps']:.1f} fps")


def test_textureless_frame_is_flagged(tmp_path):
    gt = known_path(4)
    root = write_sequence(tmp_path / "seq", gt)
    blank = np.full((H, W), 128, np.uint8)
    cv2.imwrite(str(root / "image_0" / "000002.png"), blank)
    cv2.imwrite(str(root / "image_1" / "000002.png"), blank)
    est, flagged, _ = run_stereo_vo(root, STEREO)
    assert flagged[2] and flagged[3]  # no features to reach frame 2, none from it to frame 3
    assert not flagged[1]
    assert np.all(np.diff(est[:, 2, 3]) > 0.5)  # the prior keeps the car moving forward


def test_sequence_input_errors(tmp_path):
    root = tmp_path / "seq"
    (root / "image_0").mkdir(parents=True)
    (root / "image_1").mkdir()
    with pytest.raises(InputError, match="calib.txt not found"):
        list_sequence(root)
    (root / "calib.txt").write_text(CALIB)
    img = np.zeros((8, 8), np.uint8)
    for name in ("000000.png", "000001.png"):
        cv2.imwrite(str(root / "image_0" / name), img)
    cv2.imwrite(str(root / "image_1" / "000000.png"), img)
    with pytest.raises(InputError, match="2 left images in image_0/ but 1 right images"):
        list_sequence(root)


@pytest.mark.kitti
def test_real_pair_forward_motion(kitti00):
    images = kitti00 / "images"
    k, baseline = read_calib(images / "calib.txt")
    left0 = cv2.imread(str(images / "image_0_000000.png"), cv2.IMREAD_GRAYSCALE)
    right0 = cv2.imread(str(images / "image_1_000000.png"), cv2.IMREAD_GRAYSCALE)
    previous = 0.0
    for j in range(1, 6):
        left = cv2.imread(str(images / f"image_0_00000{j}.png"), cv2.IMREAD_GRAYSCALE)
        motion = relative_motion(k, baseline, left0, right0, left, STEREO)
        assert motion.ok
        moved = np.linalg.inv(motion.T)[:3, 3]
        # Forward (+z) and growing; little sideways or vertical motion. No metric scale (see the data README).
        assert moved[2] > previous + 0.3
        assert abs(moved[0]) < 0.1 * moved[2] and abs(moved[1]) < 0.1 * moved[2]
        previous = moved[2]


def test_extract_odometry_kitti_stereo(tmp_path, grid_graph):
    from topoloc.odometry import extract_odometry

    root = write_sequence(tmp_path / "seq", known_path(6))
    odometry = make_config(odometry={"source": "kitti_stereo", "drives": {"vo": {"sequence": str(root)}},
                                     "origin": {"lat": 48.9805, "lon": 8.39, "heading_deg": 0.0}})["odometry"]
    conf = {**odometry, "drive": "vo"}
    names = {"poses": "poses.txt", "frames": "frames.csv", "stats": "odometry.json", "figure": "track.png",
             "evaluation": "evaluation.png"}
    out = {k: str(tmp_path / "out" / v) for k, v in names.items()}
    metrics = extract_odometry.run(conf, {"graph": str(grid_graph), "calib": str(root / "calib.txt")}, out)
    assert metrics["frames"] == 6 and metrics["flagged_frames"] == 0
    assert metrics["length_m"] == pytest.approx(5.0, rel=0.02)
    assert metrics["vo_fps"] > 0
