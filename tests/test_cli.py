"""``topoloc localize``: a round trip on a small map, and one-line errors for bad input."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyproj
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "localization"))
sys.path.insert(0, str(Path(__file__).resolve().parent / "trajectory"))

from localization_helpers import drive_along, dual_carriageway, irregular_grid, route_track

from topoloc.cli import main
from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.poses import poses_from_planar, write_poses

REPO = Path(__file__).resolve().parents[1]
ROUTE = [0, 1, 6, 7, 8, 13, 14, 9, 4]


@pytest.fixture(scope="module")
def small_map(tmp_path_factory):
    """A grid map, a model trained for one fast_dev_run step on it, and a drive along ROUTE with its GPS."""
    from test_train import confs

    from topoloc.trajectory.generate_dataset import generate
    from topoloc.trajectory.fitting import fit

    tmp = tmp_path_factory.mktemp("cli")
    graph, edges = irregular_grid()
    graph.nodes["lat"], graph.nodes["lon"] = 60.0, 25.0
    graph.save_graphml(tmp / "graph.graphml")
    conf = confs()
    generate(graph, conf, str(tmp / "train.parquet"), str(tmp / "val.parquet"))
    fit(conf, str(tmp / "train.parquet"), str(tmp / "val.parquet"), graph.num_edges, str(tmp / "model.ckpt"), fast_dev_run=True)
    xy = route_track(graph, ROUTE) + [385000.0, 6670000.0]  # the grid placed in Helsinki, in EPSG:3067
    graph.nodes["x"] += 385000.0
    graph.nodes["y"] += 6670000.0
    graph.geometry = [g + [385000.0, 6670000.0] for g in graph.geometry]
    graph.save_graphml(tmp / "graph.graphml")
    step = np.diff(xy, axis=0)
    yaw = np.unwrap(np.arctan2(step[:, 1], step[:, 0]))
    yaw = np.append(yaw, yaw[-1])  # the heading of travel
    local = xy - xy[0]
    write_poses(tmp / "poses.txt", poses_from_planar(local, yaw))
    lon, lat = pyproj.Transformer.from_crs("EPSG:3067", "EPSG:4326", always_xy=True).transform(xy[:, 0], xy[:, 1])
    pd.DataFrame({"frame": np.arange(len(xy)), "lat": lat, "lon": lon}).to_csv(tmp / "gps.csv", index=False)
    index = {frozenset(e): k for k, e in enumerate(edges)}
    route_edges = [index[frozenset((a, b))] for a, b in zip(ROUTE[:-1], ROUTE[1:])]
    return tmp, route_edges


def run_cli(capsys, *args):
    code = main(["localize", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_round_trip_writes_csv_and_geojson(small_map, capsys):
    tmp, route_edges = small_map
    code, out, err = run_cli(capsys, "--model", tmp / "model.ckpt", "--graph", tmp / "graph.graphml", "--poses", tmp / "poses.txt",
                             "--gps", tmp / "gps.csv", "--out", tmp / "drive", "--decoder", "hmm,strategy1,raw")
    assert code == 0, err
    assert out.startswith("topoloc localize: HMM baseline") and "drive.geojson" in out
    table = pd.read_csv(tmp / "drive.csv")
    assert set(table.localizer) == {"hmm", "strategy1", "raw"}
    assert {"step", "frame", "driven_m", "edge", "confidence", "x", "y", "lat", "lon", "path"} <= set(table.columns)
    hmm = table[table.localizer == "hmm"]
    assert len(hmm) > 40 and hmm.frame.is_monotonic_increasing
    # the map explains this noiseless drive: the baseline's path follows the route, in order
    runs = [e for i, e in enumerate(hmm.path) if i == 0 or e != hmm.path.iloc[i - 1]]
    assert runs == route_edges
    geo = json.loads((tmp / "drive.geojson").read_text())
    decoded = [f for f in geo["features"] if f["properties"]["kind"] == "decoded_edge"]
    assert [f["properties"]["edge_id"] for f in decoded] == route_edges
    lon, lat = np.array(decoded[0]["geometry"]["coordinates"]).T
    assert np.all(np.abs(lat - 60.17) < 0.05) and np.all(np.abs(lon - 24.94) < 0.1)  # WGS84, in Helsinki
    assert any(f["properties"]["kind"] == "track" for f in geo["features"])
    assert any(f["properties"]["kind"] == "positions" for f in geo["features"])  # the HMM's cells

    # without a georeference: the same answers (the map explains the drive's turns), no track
    code, out, err = run_cli(capsys, "--model", tmp / "model.ckpt", "--graph", tmp / "graph.graphml", "--poses", tmp / "poses.txt",
                             "--out", tmp / "plain", "--k", "3", "--decoder", "hmm")
    assert code == 0, err
    plain = pd.read_csv(tmp / "plain.csv")
    assert plain.path.tolist() == hmm.path.tolist() and plain.edge.tolist() == hmm.edge.tolist()
    assert not any(f["properties"]["kind"] == "track" for f in json.loads((tmp / "plain.geojson").read_text())["features"])


def test_metric_filter_needs_no_model_and_gives_a_position(small_map, capsys):
    tmp, route_edges = small_map
    code, out, err = run_cli(capsys, "--graph", tmp / "graph.graphml", "--poses", tmp / "poses.txt", "--out", tmp / "metric")
    assert code == 0, err
    table = pd.read_csv(tmp / "metric.csv")
    assert set(table.localizer) == {"metric"} and len(table) > 300  # a step every 2 m of the 800 m drive
    near_end = table[table.driven_m < table.driven_m.max() - 15.0].iloc[-1]  # on the last road, not at its end node
    assert near_end.edge == route_edges[-1] and near_end.confidence > 0.9
    assert abs(near_end.lat - 60.17) < 0.05 and abs(near_end.lon - 24.94) < 0.1
    assert "metric filter" in out and "sure since" in out and f"road {route_edges[-1]}" in out


@pytest.mark.parametrize("case", ["unknown_run", "no_store", "missing_ckpt", "no_model", "empty_poses", "standstill", "other_map", "other_map_no_georef",
                                  "bad_decoder", "bad_k"])
def test_bad_input_is_one_line(small_map, capsys, case, tmp_path):
    tmp, _ = small_map
    args = {"--model": tmp / "model.ckpt", "--graph": tmp / "graph.graphml", "--poses": tmp / "poses.txt", "--out": tmp_path / "x"}
    extra: list[str] = []
    expected = ""
    if case in ("unknown_run", "no_store", "missing_ckpt"):
        extra = ["--decoder", "strategy1"]
    if case == "unknown_run":
        from mlflow import MlflowClient

        MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}").search_experiments()  # an existing store without that run
        capsys.readouterr()
        args["--model"] = "0123456789abcdef0123456789abcdef"
        extra += ["--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}"]
        expected = "topoloc: 0123456789abcdef0123456789abcdef: no trajectory model at runs:/0123456789abcdef0123456789abcdef/model"
    elif case == "no_store":
        args["--model"] = "runs:/0123456789abcdef0123456789abcdef/model"
        extra += ["--tracking-uri", f"sqlite:///{tmp_path / 'none.db'}"]
        expected = f"topoloc: runs:/0123456789abcdef0123456789abcdef/model: no MLflow store at {tmp_path / 'none.db'}"
    elif case == "missing_ckpt":
        args["--model"] = tmp_path / "nothing.ckpt"
        expected = f"topoloc: {tmp_path / 'nothing.ckpt'}: model checkpoint not found"
    elif case == "no_model":
        del args["--model"]
        extra = ["--decoder", "strategy1"]
        expected = "topoloc: --model: strategy1 needs a trained model"
    elif case == "empty_poses":
        (tmp_path / "empty.txt").write_text("")
        args["--poses"] = tmp_path / "empty.txt"
        expected = f"topoloc: {tmp_path / 'empty.txt'}: poses file is empty"
    elif case == "standstill":
        write_poses(tmp_path / "still.txt", poses_from_planar(np.zeros((50, 2)) + np.linspace(0, 5, 50)[:, None] * [1, 0], np.zeros(50)))
        args["--poses"] = tmp_path / "still.txt"
        extra = ["--decoder", "hmm"]  # the metric filter answers (unsure) after two steps; tokens need a spacing
        expected = f"topoloc: {tmp_path / 'still.txt'}: empty trajectory: the drive covers 5.0 m, too little for any observation"
    elif case == "other_map":
        gps = pd.read_csv(tmp / "gps.csv")
        gps["lat"] += 0.5  # the same drive 55 km further north: nothing of this map is there
        gps.to_csv(tmp_path / "gps.csv", index=False)
        extra = ["--gps", str(tmp_path / "gps.csv")]
        expected = f"topoloc: {tmp / 'poses.txt'}: the georeferenced track lies"
    elif case == "other_map_no_georef":
        # a zigzag of 60 degree turns every 45 m: this grid map has no such turns
        headings = np.radians(np.repeat(np.where(np.arange(12) % 2 == 0, 30.0, -30.0), 45))
        xy = np.cumsum(np.column_stack([np.cos(headings), np.sin(headings)]), axis=0)
        write_poses(tmp_path / "zigzag.txt", poses_from_planar(xy, headings))
        args["--poses"] = tmp_path / "zigzag.txt"
        extra = ["--decoder", "hmm"]
        expected = f"topoloc: {tmp_path / 'zigzag.txt'}: nothing matches: the map turns where the drive does at only"
    elif case == "bad_decoder":
        extra = ["--decoder", "kalman"]
        expected = "topoloc: --decoder: unknown localizer 'kalman'; choose from"
    elif case == "bad_k":
        extra = ["--k", "0"]  # validated with the config, as the workflow validates its keys
        expected = "topoloc: config key 'localization.decode.k': 0 is less than the minimum of 1"
    code, out, err = run_cli(capsys, *[x for kv in args.items() for x in map(str, kv)], *extra)
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(expected), err
    assert not (tmp_path / "x.csv").exists()


def test_unexplained_drive_is_a_clear_low_confidence_answer(small_map, capsys, tmp_path):
    """A drive the map cannot explain (60 degree zigzags on a grid of right angles): no crash, never sure."""
    tmp, _ = small_map
    headings = np.radians(np.repeat(np.where(np.arange(12) % 2 == 0, 30.0, -30.0), 45))
    xy = np.cumsum(np.column_stack([np.cos(headings), np.sin(headings)]), axis=0)
    write_poses(tmp_path / "zigzag.txt", poses_from_planar(xy, headings))
    code, out, err = run_cli(capsys, "--graph", tmp / "graph.graphml", "--poses", tmp_path / "zigzag.txt", "--out", tmp_path / "z")
    assert code == 0, err
    table = pd.read_csv(tmp_path / "z.csv")
    assert (table.confidence[table.driven_m > 150] < 0.5).all()  # once the zigzags begin to tell, never sure
    assert "not sure yet" in out


def test_long_stop_and_reversing_stretch(small_map, capsys, tmp_path):
    """Odometry that stands still for five minutes (10 Hz) and backs up 20 m mid-drive: no crash, still found."""
    tmp, route_edges = small_map
    graph_xy = route_track(RoadGraph.load(tmp / "graph.graphml"), ROUTE)
    step = np.diff(graph_xy, axis=0)
    yaw = np.append(np.unwrap(np.arctan2(step[:, 1], step[:, 0])), 0.0)
    yaw[-1] = yaw[-2]
    k = len(graph_xy) // 2
    stop = np.repeat(k, 3000)  # five minutes at 10 Hz without moving
    back = np.arange(k, k - 20, -1)  # reversing 20 m, facing forward
    order = np.concatenate([np.arange(k), stop, back, np.arange(k - 20, len(graph_xy))])
    local = graph_xy[order] - graph_xy[0]
    write_poses(tmp_path / "stop.txt", poses_from_planar(local, yaw[order]))
    code, _out, err = run_cli(capsys, "--graph", tmp / "graph.graphml", "--poses", tmp_path / "stop.txt", "--out", tmp_path / "s")
    assert code == 0, err
    table = pd.read_csv(tmp_path / "s.csv")
    last = table[table.driven_m < table.driven_m.max() - 15.0].iloc[-1]
    assert last.edge == route_edges[-1] and last.confidence > 0.9
    assert (tmp_path / "s.geojson").is_file() and not list(tmp_path.glob("*.tmp*"))


def test_a_mirror_drive_prints_both_places(capsys, tmp_path):
    """An out-and-back on a dual carriageway that its mirror walk explains as well: unsure, both places printed and in
    the CSV's place columns."""
    graph, _, _ = dual_carriageway(400.0, round_ends=True)
    graph.save_graphml(tmp_path / "mirror.graphml")
    xy, yaw, _, _ = drive_along(graph, [0, 1, 4, 2, 3], start_m=50.0)
    keep = xy[:, 0] >= 100.0
    write_poses(tmp_path / "mirror.txt", poses_from_planar(xy[keep] - xy[0], yaw[keep]))
    code, out, err = run_cli(capsys, "--graph", tmp_path / "mirror.graphml", "--poses", tmp_path / "mirror.txt", "--out", tmp_path / "m")
    assert code == 0, err
    last = pd.read_csv(tmp_path / "m.csv").iloc[-1]
    assert last.confidence < 0.9 and {int(last.place1_state), int(last.place2_state)} == {0, 3}
    assert "not sure yet" in out and "top places now: 1. road" in out and "2. road" in out


def test_html_writes_the_viewer_of_the_drive(small_map, capsys):
    import re

    tmp, route_edges = small_map
    code, out, err = run_cli(capsys, "--graph", tmp / "graph.graphml", "--poses", tmp / "poses.txt", "--gps", tmp / "gps.csv",
                             "--out", tmp / "viewed", "--decoder", "metric,hmm", "--html", tmp / "viewed.html")
    assert code == 0, err
    assert "viewed.html" in out
    html = (tmp / "viewed.html").read_text(encoding="utf-8")
    blob = json.loads(re.search(r'id="topoloc-data">(.*?)</script>', html, re.S).group(1).replace("<\\/", "</"))
    assert [a["name"] for a in blob["agents"]] == ["metric", "hmm"]
    table = pd.read_csv(tmp / "viewed.csv")
    assert blob["agents"][0]["edge"] == table[table.localizer == "metric"].edge.tolist()
    assert blob["truth"] is not None and len(blob["truth"]) == len(blob["time"]["frame"])  # the georeferenced track
    assert blob["belief"]["roads"][-1][0][0] == route_edges[-1]  # the belief ends on the route's last road
