"""Benchmark of the odometry package: stereo VO speed and accuracy, and turn segmentation speed.

Prints a markdown table. Usage::

    python -m benchmarks.bench_odometry [--repeats 10] [--frames 120] [--seg-repeats 5]

Rows:

- stereo VO frames/s at 1241x376 on the real KITTI 00 pair (``relative_motion`` on
  image_0/image_1 000000 -> image_0 000001; one warm-up, median of ``--repeats``); target >= 15;
- stereo VO frames/s (``run_stereo_vo``, incl. PNG reading) and translational error on a rendered
  sequence of ``--frames`` frames at 1 m per frame, 15 deg right turn and back, staying inside the rendered
  corridor (:mod:`topoloc.odometry.synthetic`): end-point
  error and, when the path is at least 100 m long, the KITTI-style ``t_err``; target <= 2 %;
- ``segment_track`` + ``encode_segments`` on the full 4541-frame KITTI 00 drive (ground truth and
  ORB-SLAM2, ground-plane (x, z) track, ``segmentation:`` values of config/config.yaml; median of
  ``--seg-repeats``); target < 1 s.

The KITTI rows are skipped, with a message, when ``../shared/data/kitti00`` is absent.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc.config import load
from topoloc.encoding import encode_segments
from topoloc.motion.poses import planar_track, read_calib, read_poses
from topoloc.odometry.evaluate import kitti_errors
from topoloc.odometry.stereo_vo import relative_motion, run_stereo_vo
from topoloc.odometry.synthetic import known_path, write_sequence
from topoloc.segmentation import segment_track

REPO = Path(__file__).resolve().parents[1]
KITTI00 = REPO.parent / "shared" / "data" / "kitti00"
CONFIG = load(REPO / "config" / "config.yaml")
STEREO = CONFIG["odometry"]["stereo"]


def real_pair_fps(repeats: int) -> float:
    """Frames/s of ``relative_motion`` on the first KITTI 00 stereo pair and the next left image (median of ``repeats``)."""
    images = KITTI00 / "images"
    k, baseline = read_calib(images / "calib.txt")
    left0, right0, left1 = (cv2.imread(str(images / name), cv2.IMREAD_GRAYSCALE)
                            for name in ("image_0_000000.png", "image_1_000000.png", "image_0_000001.png"))
    relative_motion(k, baseline, left0, right0, left1, STEREO)  # warm-up
    seconds = []
    for _ in range(repeats):
        started = time.perf_counter()
        relative_motion(k, baseline, left0, right0, left1, STEREO)
        seconds.append(time.perf_counter() - started)
    return 1.0 / statistics.median(seconds)


def synthetic_vo(frames: int) -> dict[str, float]:
    """Frames/s, path length and errors of ``run_stereo_vo`` on a rendered sequence of ``frames`` frames."""
    gt = known_path(frames, turn_back_at=30)
    with tempfile.TemporaryDirectory() as tmp:
        started = time.perf_counter()
        root = write_sequence(Path(tmp) / "seq", gt)
        render_s = time.perf_counter() - started
        est, flagged, facts = run_stereo_vo(root, STEREO)
    length = float(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum())
    end_error = float(np.linalg.norm(est[-1, :3, 3] - gt[-1, :3, 3]))
    return {"fps": facts["vo_fps"], "length_m": length, "end_pct": 100.0 * end_error / length,
            "flagged": int(flagged.sum()), "render_s": render_s, **kitti_errors(gt, est)}


def segmentation_seconds(poses_file: Path, repeats: int) -> tuple[float, int, int]:
    """Median seconds of DP segmentation + encoding of a KITTI poses file, its frames and its tokens."""
    conf = CONFIG
    seg = conf["segmentation"]
    spacing, bins = float(conf["graph"]["virtual_node_spacing_m"]), int(conf["encoding"]["angle_bins"])
    xy = planar_track(read_poses(poses_file))
    seconds = []
    for _ in range(repeats):
        started = time.perf_counter()
        out = segment_track(xy, float(seg["tolerance_m"]), float(conf["encoding"]["heading_lookahead_m"]),
                            corner_skip_m=float(seg["corner_skip_m"]))
        encoded = encode_segments(out["lengths"], out["heading_start"], out["heading_end"], spacing, bins)
        seconds.append(time.perf_counter() - started)
    return statistics.median(seconds), len(xy), len(encoded.tokens)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10, help="timed repeats of the real-pair stereo VO step")
    parser.add_argument("--frames", type=int, default=120, help="frames of the rendered sequence (at least 60)")
    parser.add_argument("--seg-repeats", type=int, default=5, help="timed repeats of the segmentation")
    add_out_option(parser, "bench_odometry")
    args = parser.parse_args()
    with markdown_copy(args.out):
        if args.frames < 60:
            parser.error("--frames must be at least 60")
        load = os.getloadavg()
        rows: list[tuple[str, str, str]] = []
        notes: list[str] = []
        have_kitti = (KITTI00 / "images" / "calib.txt").is_file()
        if have_kitti:
            fps = real_pair_fps(args.repeats)
            rows.append((f"stereo VO, one frame at 1241x376, real KITTI 00 pair 000000 -> 000001 "
                         f"(`relative_motion`, median of {args.repeats} after 1 warm-up)", f"{fps:.1f} frames/s", ">= 15"))
        else:
            notes.append(f"KITTI rows skipped: {KITTI00} not found.")
        syn = synthetic_vo(args.frames)
        what = f"rendered {args.frames}-frame 1241x376 sequence ({syn['length_m']:.0f} m, 15 deg right turn and back)"
        rows.append((f"stereo VO on the {what}, `run_stereo_vo` incl. PNG reading", f"{syn['fps']:.1f} frames/s", ""))
        rows.append((f"stereo VO end-point error on the {what}", f"{syn['end_pct']:.2f} % of distance", "<= 2 %"))
        if syn["kitti_subsequences"]:
            rows.append((f"stereo VO KITTI-style t_err on the {what} ({syn['kitti_subsequences']} sub-sequences of 100 m)",
                         f"{syn['t_err_pct']:.2f} %, r_err {syn['r_err_deg_per_100m']:.3f} deg/100 m", "<= 2 %"))
        else:
            notes.append(f"KITTI-style t_err not computed: the rendered path is {syn['length_m']:.0f} m, shorter than 100 m.")
        notes.append(f"rendered sequence: {syn['flagged']} flagged frames, rendering took {syn['render_s']:.1f} s (not timed).")
        if have_kitti:
            for name in ("gt", "orbslam2"):
                seconds, frames, tokens = segmentation_seconds(KITTI00 / "poses" / f"00_{name}.txt", args.seg_repeats)
                rows.append((f"`segment_track` + `encode_segments`, KITTI 00 `00_{name}.txt` ({frames} frames, {tokens} tokens; "
                             f"median of {args.seg_repeats})", f"{1000 * seconds:.1f} ms", "< 1 s"))
        print(f"load average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} CPUs)\n")
        print("| what | value | target |\n|---|---:|---|")
        for what, value, target in rows:
            print(f"| {what} | {value} | {target} |")
        for note in notes:
            print(f"\n{note}")


if __name__ == "__main__":
    main()
