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


@pytest.mark.kitti
def test_kitti00_ground_truth_made_a_noisy_odometry(kitti00, kitti00_graph, tmp_path):
    """A drive's noise (odometry.drives.<drive>.noise, seeded): the ground truth at a stereo-VO level, evaluated
    against itself; the same seed gives the same poses."""
    level = {"scale_error": 0.01, "distance_noise": 0.01, "heading_drift_deg_per_100m": 0.5, "heading_noise_deg": 0.02}
    conf = {**CONF, "source": "kitti_poses", "drive": "vo", "drives": {"vo": {"noise": level, "noise_seed": 0}}}
    metrics = extract_odometry.run(conf, kitti_inputs(kitti00, kitti00_graph, "00_gt.txt"), odometry_outputs(tmp_path / "a", "vo"))
    assert 1.0 < metrics["t_err_pct"] < 2.0 and 0.3 < metrics["r_err_deg_per_100m"] < 0.8, metrics
    assert metrics["labels_unconnected_changes"] == 0  # labels from the ground truth, as before
    extract_odometry.run(conf, kitti_inputs(kitti00, kitti00_graph, "00_gt.txt"), odometry_outputs(tmp_path / "b", "vo"))
    assert (tmp_path / "a" / "vo" / "poses.txt").read_text() == (tmp_path / "b" / "vo" / "poses.txt").read_text()
    assert json.loads((tmp_path / "a" / "vo" / "odometry.json").read_text())["noise"] == {**level, "seed": 0}


def straight_drive(folder, frames=60):
    """A 60 m straight KITTI poses file (forward along +z)."""
    folder.mkdir(parents=True, exist_ok=True)
    poses = folder / "poses.txt"
    poses.write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {k:.1f}\n" for k in range(frames)))
    return poses


def test_a_drive_of_another_city_stops_extract_odometry(grid_graph, tmp_path):
    """GPS of Helsinki on a Karlsruhe map: one line naming the GPS file, before anything is written."""
    poses = straight_drive(tmp_path / "in")
    gps = tmp_path / "in" / "gps.csv"
    gps.write_text("frame,lat,lon\n" + "".join(f"{k},{60.17 + k * 9e-6:.7f},24.94\n" for k in range(60)))
    out = odometry_outputs(tmp_path, "d")
    conf = {**CONF, "source": "kitti_poses", "drive": "d"}
    with pytest.raises(InputError) as info:
        extract_odometry.run(conf, {"graph": str(grid_graph), "poses": str(poses), "gps": str(gps)}, out)
    message = str(info.value)
    assert message.startswith(f"{gps}: drive d lies 1,") and " km (median) from the roads of the map (0% of its frames within 5 m" in message
    assert message.endswith("the drive is not in this region")
    assert not (tmp_path / "d").exists()


def test_a_wrong_origin_stops_extract_odometry(grid_graph, tmp_path):
    """Without GPS the origin places the drive: an origin 2.5 km away names odometry.origin; on the map it passes."""
    poses = straight_drive(tmp_path / "in")
    conf = {**CONF, "source": "kitti_poses", "drive": "d", "origin": {"lat": 49.0, "lon": 8.42, "heading_deg": 0.0}}
    out = odometry_outputs(tmp_path, "d")
    with pytest.raises(InputError, match=r"^odometry.origin: drive d lies 2,\d\d\d m \(median\) from the roads"):
        extract_odometry.run(conf, {"graph": str(grid_graph), "poses": str(poses)}, out)
    on_map = {**conf, "origin": {"lat": 48.98, "lon": 8.3905, "heading_deg": 90.0}}  # along the southern street
    metrics = extract_odometry.run(on_map, {"graph": str(grid_graph), "poses": str(poses)}, out)
    assert metrics["labels_within_5m"] == 1.0
