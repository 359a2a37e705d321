"""The extract_odometry and segment_trajectory stages on simulated and real drives."""

import json
import time

import numpy as np
import pandas as pd
import pytest

from tests.conftest import make_config
from topoloc.errors import InputError
from topoloc.odometry import extract_odometry, segment_trajectory

CONFIG = make_config(odometry={"source": "simulated", "simulated": {"drives": 2, "length_m": 1500, "seed": 3}})
CONF = CONFIG["odometry"]
SEG = {k: CONFIG[k] for k in ("segmentation", "encoding")}


def odometry_outputs(tmp_path, drive):
    names = {"poses": "poses.txt", "frames": "frames.csv", "stats": "odometry.json", "figure": "track.png",
             "evaluation": "evaluation.png"}
    return {k: str(tmp_path / drive / v) for k, v in names.items()}


def segment_outputs(tmp_path, drive):
    names = {"tokens": "tokens.csv", "segments": "segments.csv", "stats": "segments.json", "figure": "segments.png"}
    return {k: str(tmp_path / drive / v) for k, v in names.items()}


def kitti_inputs(kitti00, graph, poses):
    return {"graph": str(graph), "poses": str(kitti00 / "poses" / poses),
            "ground_truth": str(kitti00 / "poses" / "00_gt.txt"), "times": str(kitti00 / "poses" / "00_times.txt"),
            "gps": str(kitti00 / "gps" / "00_latlon.csv")}


def test_simulated_drive(grid_graph, tmp_path):
    out = odometry_outputs(tmp_path, "sim01")
    metrics = extract_odometry.run({**CONF, "drive": "sim01"}, {"graph": str(grid_graph)}, out)
    frames = pd.read_csv(out["frames"])
    assert metrics["length_m"] >= 1500 * 1.0
    assert metrics["labels_within_5m"] == 1.0
    assert metrics["labels_unconnected_changes"] == 0
    assert (frames.edge_id == frames.true_edge_id).mean() > 0.97
    assert 0.2 < metrics["t_err_pct"] < 5.0
    seg_out = segment_outputs(tmp_path, "sim01")
    seg = segment_trajectory.run({**SEG, "drive": "sim01"}, {"graph": str(grid_graph), "frames": out["frames"]}, seg_out)
    tokens = pd.read_csv(seg_out["tokens"])
    assert seg["turn_tokens"] >= 3
    assert set(tokens.edge_id) <= set(frames.edge_id)
    # Grid: every turn is about 90 (left), 180 or 270 (right) degrees, bins 5, 10 and 15 of 20.
    assert set(tokens.token[tokens.kind == "turn"]) <= {4, 5, 6, 9, 10, 11, 14, 15, 16}


def test_simulation_is_reproducible(grid_graph, tmp_path):
    a = extract_odometry.run({**CONF, "drive": "sim00"}, {"graph": str(grid_graph)}, odometry_outputs(tmp_path / "a", "sim00"))
    b = extract_odometry.run({**CONF, "drive": "sim00"}, {"graph": str(grid_graph)}, odometry_outputs(tmp_path / "b", "sim00"))
    assert a == b


def test_bad_gps_writes_nothing(grid_graph, tmp_path, kitti00):
    gps = tmp_path / "short.csv"
    gps.write_text("frame,lat,lon\n0,48.98,8.39\n")
    inputs = {**kitti_inputs(kitti00, grid_graph, "00_gt.txt"), "gps": str(gps)}
    out = odometry_outputs(tmp_path, "gt")
    with pytest.raises(InputError, match="short.csv: GPS file covers 1 of the 4541"):
        extract_odometry.run({**CONF, "source": "kitti_poses", "drive": "gt"}, inputs, out)
    assert not (tmp_path / "gt").exists() or not any((tmp_path / "gt").iterdir())


@pytest.mark.kitti
@pytest.mark.parametrize("poses", ["00_gt.txt", "00_orbslam2.txt"])
def test_kitti00_labels_and_segments(kitti00, kitti00_graph, tmp_path, poses):
    conf = {**CONF, "source": "kitti_poses", "drive": "d"}
    out = odometry_outputs(tmp_path, "d")
    metrics = extract_odometry.run(conf, kitti_inputs(kitti00, kitti00_graph, poses), out)
    frames = pd.read_csv(out["frames"])
    assert len(frames) == 4541
    assert (frames.edge_distance_m <= 5.0).mean() >= 0.95
    assert metrics["labels_unconnected_changes"] == 0
    stats = json.loads(open(out["stats"]).read())
    assert stats["georeference"]["rms_m"] < 2.0
    seg_out = segment_outputs(tmp_path, "d")
    started = time.perf_counter()
    seg = segment_trajectory.run({**SEG, "drive": "d"}, {"graph": str(kitti00_graph), "frames": out["frames"]}, seg_out)
    assert time.perf_counter() - started < 5.0  # whole stage including the figure
    assert seg["segmentation_s"] < 1.0
    assert 20 <= seg["segments"] <= 80
    tokens = pd.read_csv(seg_out["tokens"])
    # Each token's labelled edge is within 10 m of where the ground truth is at that frame.
    gt_xy = frames[["gt_x", "gt_y"]].to_numpy()[tokens.frame]
    assert np.all(np.isfinite(gt_xy))
    assert (frames.edge_distance_m.to_numpy()[tokens.frame] <= 5.0).mean() >= 0.95
