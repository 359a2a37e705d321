"""The four place stages on the hand-made town, chained as the workflow chains them (small images and budgets)."""

from __future__ import annotations

import json
from pathlib import Path

import lightning as L
import numpy as np
import pandas as pd
import pytest
import torch

from tests.place.conftest import place_conf, render_conf
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.place import build_topometric_map, localize_repeat, render_places, train_retrieval
from topoloc.place.images import PlaceSet, polyline_distance, route_path
from topoloc.place.network import SiameseNet
from topoloc.place.pair_data import PairData
from topoloc.place.train_retrieval import build_model, window_top1
from topoloc.render.conditions import check_conditions


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


class ChanceScores:
    """A retrieval model that scores every pair at random: chance retrieval."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def embed(self, images: np.ndarray) -> np.ndarray:
        return np.zeros((len(images), 1), np.float32)

    def same_place(self, query: np.ndarray, refs: np.ndarray) -> np.ndarray:
        return self.rng.random(len(refs))


#: The mean of ``window_top1_<condition>`` over the repeat conditions that retrieval must reach (chance does not).
RETRIEVAL_TOP1 = 0.5
#: The trained network's validation loss (4 steps) is under this share of that of every network with random weights.
LOSS_SHARE = 0.95


def test_training_outputs(stages):
    metrics, place = stages["train_metrics"], stages["place"]
    assert metrics["steps"] == 4 and metrics["epochs"] == 1
    assert {f"best/val/acc_{name}" for name in ("clear_noon", "overcast", "sunset", "rain", "fog", "night")} <= set(metrics)
    # Training lowered the validation loss below that of random weights (three draws), on the same validation pairs.
    places = PlaceSet.load(stages["train"]["places"])
    data = PairData(places, check_conditions(place)["train"], place["train"], place["pairs"])
    trainer = L.Trainer(accelerator="cpu", logger=False, enable_progress_bar=False, enable_model_summary=False)
    random_losses = []
    for seed in (1, 2, 3):
        torch.manual_seed(seed)
        untrained = build_model(place, places.images.shape[-1], places.conditions)
        random_losses.append(trainer.validate(untrained, datamodule=data, verbose=False)[0]["val/loss"])
    assert metrics["best/val/loss"] < LOSS_SHARE * min(random_losses), (metrics["best/val/loss"], random_losses)
    # Retrieval in the localization's window finds a place within 5 m more often than chance retrieval does.
    repeat = place["repeat_conditions"]
    top1 = np.mean([metrics[f"window_top1_{c}"] for c in repeat])
    chance = window_top1(ChanceScores(0), places, data.val_idx, places.conditions.index(place["teach_condition"]),
                         int(place["localize"]["window"]))
    chance_top1 = np.mean([chance[f"window_top1_{c}"] for c in repeat])
    assert top1 >= RETRIEVAL_TOP1 > chance_top1, (top1, chance_top1)
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
