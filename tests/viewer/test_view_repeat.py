"""The teach-and-repeat viewer (rule view_repeat) on a small hand-made map, repeat drive and images."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from viewer_helpers import EPISODES, embedded

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.viewer.page import latlon_of
from topoloc.viewer.view_repeat import run


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


def test_the_closed_loop_drives_of_the_condition_are_replayed_by_progress(repeat_inputs, tmp_path):
    conf = {"viewer": load(None, {"viewer": {"condition": "night"}})["viewer"], "region": "test"}
    run(conf, repeat_inputs, {"html": str(tmp_path / "repeat.html")})
    blob = embedded(tmp_path / "repeat.html")
    drives = blob["drives"]
    assert [d["key"] for d in drives] == EPISODES[:2]  # the night drives only
    success, failed = drives
    assert failed["label"] == "replay (place_loop), route 0, repeat 0: off_road after 150 m" and failed["outcome"] == "off_road"
    traces = pd.read_csv(repeat_inputs["traces"])
    trace = traces[traces.episode == EPISODES[1]]
    latlon = latlon_of(RoadGraph.load(repeat_inputs["graph"]).crs)
    assert failed["pos"] == latlon(trace[["x", "y"]].to_numpy()) and failed["end"] == failed["pos"][-1]
    assert failed["text"][0] == "0.0 s · 5.0 m/s · command left (vertex 20) · steer +0.00"
    # each trace point shown from the first row that has driven as far as the route's start plus its progress
    driven = np.asarray(blob["time"]["driven_m"])
    expected = [int(np.flatnonzero(driven >= 100.0 + s)[0]) for s in trace.s_m]
    assert failed["idx"] == expected and driven[failed["idx"][0] - 1] < 100.0 <= driven[failed["idx"][0]]
    assert success["idx"][-1] == len(driven) - 1  # beyond the repeat drive: at its last row


def test_traces_that_are_not_traces_name_the_file(repeat_inputs, tmp_path):
    pd.DataFrame({"episode": ["x"]}).to_csv(repeat_inputs["traces"], index=False)
    conf = {"viewer": load(None, {})["viewer"], "region": "test"}
    with pytest.raises(InputError, match="traces.csv.gz.*no 'route' column"):
        run(conf, repeat_inputs, {"html": str(tmp_path / "repeat.html")})
