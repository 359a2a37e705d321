"""The teach-and-repeat viewer (rule view_repeat) on a small hand-made map, repeat drive and images."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from viewer_helpers import OFFSET, embedded, small_drive

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.viewer.view_repeat import run


@pytest.fixture()
def repeat_inputs(tmp_path):
    graph, xy, _, _ = small_drive()
    graph.save_graphml(tmp_path / "graph.graphml")
    teach = xy[::5]
    commands = np.where(np.arange(len(teach)) % 20 == 0, "turn_left", "follow")
    pd.DataFrame({"vertex": np.arange(len(teach)), "x": teach[:, 0], "y": teach[:, 1], "s": 5.0 * np.arange(len(teach)),
                  "gt_x": teach[:, 0], "gt_y": teach[:, 1], "command": commands}).to_csv(tmp_path / "vertices.csv", index=False)
    repeat = xy[2::5][:60]
    rows = []
    for condition in ("fog", "night"):
        for method, shift in (("siamese network", 0), ("odometry only", 3)):
            for f, p in enumerate(repeat):
                vertex = min(f + shift, len(teach) - 1) if not (method == "odometry only" and f == 7) else -1
                rows.append({"condition": condition, "method": method, "frame": f, "gt_x": p[0], "gt_y": p[1],
                             "vertex": vertex, "s": 0.0, "error_m": float(np.hypot(*(teach[vertex] - p))) if vertex >= 0 else np.nan,
                             "event": "match", "score": 0.5})
    pd.DataFrame(rows).to_csv(tmp_path / "frames.csv", index=False)
    images = np.random.default_rng(0).integers(0, 255, size=(2, len(repeat), 12, 40, 3), dtype=np.uint8)
    np.savez(tmp_path / "places.npz", images=images, conditions=np.array(["fog", "night"]))
    pd.DataFrame({"route": 0, "route_start_m": 100.0, "route_length_m": 400.0, "condition": ["night", "night", "fog"],
                  "agent": ["Topo-LP (ground truth)", "replay (place_loop)", "replay (place_loop)"],
                  "outcome": ["success", "off_road", "off_road"], "success": [True, False, False],
                  "progress_m": [400.0, 150.0, 20.0]}).to_csv(tmp_path / "episodes.csv", index=False)
    return {"graph": str(tmp_path / "graph.graphml"), "vertices": str(tmp_path / "vertices.csv"),
            "frames": str(tmp_path / "frames.csv"), "repeat": str(tmp_path / "places.npz"),
            "episodes": str(tmp_path / "episodes.csv")}


def test_the_repeat_viewer_shows_each_method_its_vertex_and_the_camera(repeat_inputs, tmp_path):
    conf = {"viewer": load(None, {"viewer": {"condition": "night", "image_every": 4}})["viewer"], "region": "test"}
    metrics = run(conf, repeat_inputs, {"html": str(tmp_path / "repeat.html")})
    blob = embedded(tmp_path / "repeat.html")
    assert metrics["methods"] == 2 and metrics["frames"] == 60 and "night" in blob["title"]
    siamese, odometry = blob["agents"]
    assert siamese["name"] == "siamese network" and siamese["unit"] == "vertex" and siamese["edge"][:3] == [0, 1, 2]
    assert odometry["pos"][7] is None and odometry["conf"][7] == 0.0  # not localized at frame 7
    vertices = pd.read_csv(repeat_inputs["vertices"])
    lat, lon = siamese["pos"][10]
    assert lat == pytest.approx(blob["lines"][0]["latlngs"][10][0]) and lon == pytest.approx(blob["lines"][0]["latlngs"][10][1])
    assert len(blob["lines"][0]["latlngs"]) == len(vertices)
    assert len(blob["images"]["src"]) == 15 and all(s.startswith("data:image/jpeg;base64,") for s in blob["images"]["src"])
    assert blob["text"]["text"][0] == "siamese network: vertex 0, command turn_left, error 2.0 m"
    # route following: the route along the teach route, and where the failed episode of this condition stopped
    assert blob["lines"][1]["name"] == "route following: route 0 (400 m)" and len(blob["lines"][1]["latlngs"]) == 81
    fails = [m for m in blob["marks"] if m["kind"] == "fail"]
    assert len(fails) == 1 and fails[0]["label"] == "replay (place_loop): off_road after 150 m of route 0"
    assert [fails[0]["lat"], fails[0]["lon"]] == blob["lines"][0]["latlngs"][50]  # s = 100 + 150 m: vertex 50
    assert blob["time"]["t_s"] is None and blob["truth"][0][0] == pytest.approx(60.15, abs=0.01)


def test_an_unknown_condition_names_the_key(repeat_inputs, tmp_path):
    conf = {"viewer": load(None, {"viewer": {"condition": "snow"}})["viewer"], "region": "test"}
    with pytest.raises(InputError, match="viewer.condition"):
        run(conf, repeat_inputs, {"html": str(tmp_path / "repeat.html")})
