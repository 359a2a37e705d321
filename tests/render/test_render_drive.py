"""The render_drive stage: KITTI layout, determinism, the stereo VO on its output, and input errors."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from tests.conftest import make_config, write_osm
from tests.render.conftest import render_conf, render_outputs
from topoloc.errors import InputError
from topoloc.motion.poses import read_calib, read_gps, read_poses, read_times
from topoloc.odometry import extract_odometry
from topoloc.render import render_drive
from topoloc.render.conditions import parse_drive, rendered_drive_names
from topoloc.render.rig import StereoRig
from topoloc.render.scene import read_buildings


def file_bytes(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (relative name -> bytes)."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_kitti_layout_and_stereo_vo(town, tmp_path):
    conf = render_conf(length_m=160.0)
    out = render_outputs(tmp_path / "ren00_clear_noon")
    facts = render_drive.run({**conf, "drive": "ren00_clear_noon"}, {"graph": str(town["graph"]), "osm": str(town["osm"])}, out)
    n = int(facts["frames"])
    lefts = sorted(Path(out["left"]).glob("*.png"))
    assert [p.name for p in lefts] == [f"{k:06d}.png" for k in range(n)]
    assert [p.name for p in sorted(Path(out["right"]).glob("*.png"))] == [p.name for p in lefts]
    image = cv2.imread(str(lefts[0]), cv2.IMREAD_UNCHANGED)
    assert image.shape == (188, 620) and image.dtype == np.uint8
    K, baseline = read_calib(out["calib"])
    rig = StereoRig.kitti(620, 188, conf["baseline_m"], conf["camera_height_m"])
    assert np.allclose(K, rig.K) and baseline == pytest.approx(0.54)
    gt = read_poses(out["poses"])
    assert len(gt) == n and np.allclose(gt[0], np.eye(4))
    assert np.allclose(np.diff(read_times(out["times"], n)), 0.1)
    assert read_gps(out["gps"], n).shape == (n, 2)
    route = pd.read_csv(out["route"])
    assert len(route) == n and set(route.columns) >= {"x", "y", "yaw_deg", "edge_id"}
    stats = json.loads(Path(out["stats"]).read_text())
    assert stats["buildings_osm"] > 0 and stats["condition"]["name"] == "clear_noon"
    assert stats["length_m"] == pytest.approx(160.0, abs=1.5)
    assert cv2.imread(out["sheet"]).shape[0] > 2 * 188  # two conditions

    # extract_odometry runs the stereo VO on it exactly as on a KITTI sequence.
    odo = {"poses": "poses.txt", "frames": "frames.csv", "stats": "odometry.json", "figure": "track.png",
           "evaluation": "evaluation.png"}
    odo_out = {k: str(tmp_path / "odometry" / v) for k, v in odo.items()}
    inputs = {"graph": str(town["graph"]), "calib": out["calib"], "ground_truth": out["poses"], "times": out["times"],
              "gps": out["gps"], "truth": out["route"]}
    odo_conf = {**make_config(odometry={"source": "rendered"})["odometry"], "drive": "ren00_clear_noon"}
    metrics = extract_odometry.run(odo_conf, inputs, odo_out)
    print(f"rendered 160 m drive: VO t_err {metrics['t_err_pct']:.2f} %, r_err {metrics['r_err_deg_per_100m']:.3f} deg/100 m")
    assert metrics["flagged_frames"] == 0
    assert metrics["kitti_subsequences"] >= 3
    assert metrics["t_err_pct"] <= 3.0
    assert metrics["labels_agreement_with_simulation"] >= 0.9
    assert json.loads(Path(odo_out["stats"]).read_text())["georeference"]["ground_truth"]["rms_m"] < 0.01


def test_same_seed_same_bytes(town, tmp_path):
    conf = render_conf(length_m=12.0, width=320, height=96, conditions=["rain"], sheet={"conditions": ["rain"], "frames": 1})
    inputs = {"graph": str(town["graph"]), "osm": str(town["osm"])}
    runs = []
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        render_drive.run({**conf, "seed": seed, "drive": "ren00_rain"}, inputs, render_outputs(tmp_path / name))
        runs.append(file_bytes(tmp_path / name))
    a, b, c = runs
    a.pop("render.json"), b.pop("render.json")  # holds timings
    assert a == b
    assert a["image_0/000003.png"] != c["image_0/000003.png"]


def test_conditions_share_the_route(town, tmp_path):
    conf = render_conf(length_m=8.0, width=320, height=96, sheet={"conditions": [], "frames": 1})
    inputs = {"graph": str(town["graph"]), "osm": str(town["osm"])}
    for drive in ("ren01_clear_noon", "ren01_night"):
        render_drive.run({**conf, "drive": drive}, inputs, render_outputs(tmp_path / drive))
    day, night = (tmp_path / d for d in ("ren01_clear_noon", "ren01_night"))
    assert (day / "poses.txt").read_bytes() == (night / "poses.txt").read_bytes()
    assert (day / "image_0" / "000002.png").read_bytes() != (night / "image_0" / "000002.png").read_bytes()


def test_drive_names_and_bad_inputs(town, tmp_path):
    assert rendered_drive_names(render_conf(routes=2, conditions=["clear_noon", "fog"])) == [
        "ren00_clear_noon", "ren00_fog", "ren01_clear_noon", "ren01_fog"]
    assert parse_drive("ren12_sunset") == (12, "sunset")
    with pytest.raises(InputError, match=r"^render.conditions.1: unknown condition 'snow'"):
        rendered_drive_names(render_conf(conditions=["fog", "snow"]))
    with pytest.raises(InputError, match=r"^drive: 'sim00' is not a rendered drive name"):
        parse_drive("sim00")
    inputs = {"graph": str(town["graph"]), "osm": str(town["osm"])}
    cases = [({"width": 32}, r"^render.width: image size 32x188 is too small"),
             ({"sheet": {"conditions": ["dusk"], "frames": 1}}, r"^render.sheet.conditions.0: unknown condition 'dusk'"),
             ({"length_m": 0.5}, r"^render.length_m: ")]
    for override, message in cases:
        out = render_outputs(tmp_path / "bad")
        with pytest.raises(InputError, match=message):
            render_drive.run({**render_conf(**override), "drive": "ren00_clear_noon"}, inputs, out)
        assert not (tmp_path / "bad" / "image_0").exists()


def test_buildings_of_an_unsorted_file(tmp_path):
    square = [(0, 0), (1, 0), (1, 1), (0, 1)]
    nodes = {1 + i: (8.39 + 0.0002 * dx, 48.98 + 0.0002 * dy) for i, (dx, dy) in enumerate(square)}
    nodes.update({11 + i: (8.391 + 0.0002 * dx, 48.98 + 0.0002 * dy) for i, (dx, dy) in enumerate(square)})
    ways = [(20, [11, 12, 13, 14, 11], {"building": "yes", "height": "7"}), (10, [1, 2, 3, 4, 1], {"building": "yes"})]
    osm = write_osm(tmp_path / "unsorted.osm", nodes, ways)
    conf = {"default_height_m": [9.0, 24.0], "level_height_m": 3.2}
    buildings = read_buildings(osm, "EPSG:32632", conf, seed=0)
    assert sorted(b.key for b in buildings) == [10, 20]
    assert {b.key: b.height for b in buildings}[20] == 7.0
