"""The four place stages on the hand-made town, chained as the workflow chains them (small images and budgets)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.place.conftest import place_conf, render_conf
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.place import build_topometric_map, localize_repeat, render_places, train_retrieval
from topoloc.place.images import PlaceSet, polyline_distance, route_path
from topoloc.place.network import SiameseNet


def outputs(root: Path, names: dict[str, str]) -> dict[str, str]:
    return {k: str(root / v) for k, v in names.items()}


@pytest.fixture(scope="module")
def stages(town, tmp_path_factory):
    """Run render_places (3 splits), train_retrieval, build_topometric_map and localize_repeat once."""
    root = tmp_path_factory.mktemp("place")
    place, render = place_conf(), render_conf(length_m=160.0)
    inputs = {"graph": str(town["graph"]), "osm": str(town["osm"])}
    out = {}
    for split in ("train", "teach", "repeat"):
        out[split] = outputs(root / split, {"places": "places.npz", "stats": "stats.json", "sheet": "sheet.png"})
        render_places.run({"split": split, "render": render, "place": place}, inputs, out[split])
    out["retrieval"] = outputs(root / "retrieval", {"model": "model.ckpt", "history": "history.csv",
                                                    "metrics": "train_metrics.json", "figure": "training.png"})
    out["train_metrics"] = train_retrieval.run(place, {"places": out["train"]["places"]}, out["retrieval"])
    out["map"] = outputs(root / "map", {"map": "map.npz", "vertices": "vertices.csv", "stats": "stats.json",
                                        "figure": "map.png"})
    build_topometric_map.run(place, {"model": out["retrieval"]["model"], "teach": out["teach"]["places"],
                                     "graph": inputs["graph"]}, out["map"])
    out["loc"] = outputs(root / "loc", {"frames": "frames.csv", "summary": "summary.csv", "metrics": "metrics.json",
                                        "table": "tables.md", "bars": "conditions.png", "errors": "errors.png"})
    out["loc_metrics"] = localize_repeat.run(place, {"model": out["retrieval"]["model"], "map": out["map"]["map"],
                                                     "repeat": out["repeat"]["places"]}, out["loc"])
    out["render"], out["place"] = render, place
    return out


def test_place_sets(stages, town):
    graph = RoadGraph.load(town["graph"])
    route = route_path(graph, stages["render"], 0)
    train = PlaceSet.load(stages["train"]["places"])
    teach = PlaceSet.load(stages["teach"]["places"])
    repeat = PlaceSet.load(stages["repeat"]["places"])
    assert train.conditions == ["clear_noon", "overcast", "sunset", "rain", "fog", "night"]
    assert train.images.shape[2:] == (48, 64, 3) and train.images.dtype == np.uint8
    assert set(np.unique(train.route)) == {0, 1, 2}
    # training places are disjoint from the evaluation route
    assert polyline_distance(train.xy, route.xy).min() >= 20.0
    assert teach.conditions == ["clear_noon"] and np.allclose(teach.xy, route.xy) and np.all(teach.edge >= 0)
    assert repeat.conditions == ["overcast", "sunset", "rain", "fog", "night"]
    # repeat frames every 1.1 m (up to the weave), within 0.5 m + a bit of the teach path
    assert np.median(np.hypot(*np.diff(repeat.xy, axis=0).T)) == pytest.approx(1.1, abs=0.05)
    assert polyline_distance(repeat.xy, route.xy, 0.1).max() < 0.6
    stats = json.loads(Path(stages["train"]["stats"]).read_text())
    assert stats["min_distance_to_route_m"] >= 20.0 and stats["images"] == 6 * len(train)


def test_training_outputs(stages):
    metrics = stages["train_metrics"]
    assert metrics["steps"] == 4 and metrics["epochs"] >= 0
    for name in ("clear_noon", "overcast", "sunset", "rain", "fog", "night"):
        assert 0.0 <= metrics[f"best/val/acc_{name}"] <= 1.0
    assert {f"window_top1_{c}" for c in ("overcast", "fog", "night")} <= set(metrics)
    history = pd.read_csv(stages["retrieval"]["history"])
    assert history["train/loss"].notna().any() and history["val/loss"].notna().any()
    assert metrics["best/val/loss"] == pytest.approx(history["val/loss"].min())
    # the kept checkpoint carries the condition names of its val/acc_<condition> metrics
    kept = SiameseNet.load_from_checkpoint(stages["retrieval"]["model"], map_location="cpu")
    assert kept.condition_names == PlaceSet.load(stages["train"]["places"]).conditions
    assert Path(stages["retrieval"]["figure"]).stat().st_size > 1000


def test_map_and_localization_outputs(stages):
    vertices = pd.read_csv(stages["map"]["vertices"])
    teach = PlaceSet.load(stages["teach"]["places"])
    assert len(vertices) == len(teach)
    assert set(vertices.command) <= {"follow", "left", "right", "straight"}
    stats = json.loads(Path(stages["map"]["stats"]).read_text())
    assert stats["vertices"] == len(teach) and stats["embed_images_per_s"] > 0
    frames = pd.read_csv(stages["loc"]["frames"])
    repeat = PlaceSet.load(stages["repeat"]["places"])
    # place.localize.localizers: the loop and the filter with each scorer, odometry once; five conditions
    assert list(dict.fromkeys(frames.method)) == ["siamese network", "siamese network + filter", "raw correlation",
                                                  "raw correlation + filter", "odometry only"]
    assert len(frames) == 5 * 5 * len(repeat)
    summary = pd.read_csv(stages["loc"]["summary"])
    assert np.all((summary.within_2m <= summary.within_5m) & (summary.within_5m <= 1.0))
    table = Path(stages["loc"]["table"]).read_text()
    assert "| method | Mean | overcast | sunset | rain | fog (held out) | night |" in table
    metrics = stages["loc_metrics"]
    assert metrics["network_within_5m_fog"] == pytest.approx(summary.set_index(["method", "condition"]).loc[
        ("siamese network", "fog"), "within_5m"], abs=1e-4)
    fog = frames[(frames.method == "siamese network") & (frames.condition == "fog")]
    assert metrics["network_within_5m_fog"] == pytest.approx(np.mean(fog.error_m <= 5.0), abs=1e-3)
    assert {"network_filter_within_5m_min", "correlation_filter_within_2m_night"} <= set(metrics)
    # a 160 m route: odometry alone stays within 5 m, and the filter with a barely trained network (4 steps: its
    # scores say little) falls back on the odometry instead of following them astray
    within = summary.set_index(["method", "condition"]).within_5m
    assert within["odometry only"].min() > 0.9 and within["siamese network + filter"].min() > 0.9


def test_bad_inputs_name_the_key(town, tmp_path):
    inputs = {"graph": str(town["graph"]), "osm": str(town["osm"])}
    out = outputs(tmp_path, {"places": "p.npz", "stats": "s.json", "sheet": "s.png"})
    bad = place_conf(teach_condition="overcast")
    with pytest.raises(InputError, match=r"^place.repeat_conditions: must not contain the teach condition"):
        render_places.run({"split": "teach", "render": render_conf(), "place": bad}, inputs, out)
    bad = place_conf(train={"conditions": ["clear_noon", "overcast", "sunset", "rain", "fog", "night"]})
    with pytest.raises(InputError, match=r"^place.train.conditions: keep at least one condition out"):
        render_places.run({"split": "train", "render": render_conf(), "place": bad}, inputs, out)
    bad = place_conf(train={"min_distance_m": 5000.0})
    with pytest.raises(InputError, match=r"^place.train.min_distance_m: "):
        render_places.run({"split": "train", "render": render_conf(length_m=160.0), "place": bad}, inputs, out)
    assert not Path(out["places"]).exists()
    with pytest.raises(InputError, match=r"^place.network.weights: "):
        train_retrieval.build_model(place_conf(network={"weights": str(tmp_path / "none.pt")}), 3, ["a", "b"])
