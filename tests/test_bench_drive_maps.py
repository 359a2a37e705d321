"""benchmarks/bench_drive_maps: controllers trained on some maps, checked on another; its junction and seed columns."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import lightning as L
import pandas as pd
import pytest
import torch

from benchmarks.bench_drive_maps import (
    _check_routes,
    _init_worker,
    check_length,
    junction_columns,
    main,
    summary,
)
from tests.render.conftest import town  # noqa: F401 (the fixture)
from topoloc.config import dotted_overrides, load
from topoloc.drive.junctions import FAILED, NOT_REACHED, TAKEN
from topoloc.place.network import SiameseNet

REPO = Path(__file__).resolve().parents[1]


def test_the_junction_columns_count_only_the_junctions_reached():
    rows = pd.DataFrame({"result": [TAKEN, TAKEN, FAILED, NOT_REACHED, TAKEN],
                         "turn": ["straight", "left", "right", "left", "U-turn"]})
    assert junction_columns(rows) == {"junctions taken": 0.75, "turns taken": 2 / 3, "junctions reached": 4.0}
    none = junction_columns(pd.DataFrame({"result": [NOT_REACHED], "turn": ["left"]}))
    assert math.isnan(none["junctions taken"]) and math.isnan(none["turns taken"]) and none["junctions reached"] == 0.0
    assert junction_columns(pd.DataFrame())["junctions reached"] == 0.0


def test_the_summary_gives_each_case_its_mean_and_spread_over_seeds():
    rows = pd.DataFrame({"case": ["a:b", "a:b", "c:b"], "seed": [0, 1, 0], "success_rate": [0.5, 0.7, 0.9],
                         "turns taken": [float("nan"), float("nan"), 1.0]})
    out = summary(rows).set_index("case")
    assert out.loc["a:b", "seed"] == "2 seeds" and out.loc["a:b", "success_rate"] == "0.60 +- 0.14"
    assert out.loc["a:b", "turns taken"] == "-"  # no seed reached a turn: no rate, not 0
    assert out.loc["c:b", "success_rate"] == "0.90 +- 0.00"


@pytest.mark.slow
def test_a_controller_trained_on_one_map_is_checked_on_another(town, tmp_path):  # noqa: F811 (the fixture)
    maps = {}
    for name in ("one", "two"):  # the same town twice: two map folders as build_graph leaves them
        (tmp_path / name / "graph").mkdir(parents=True)
        (tmp_path / name / "osm").mkdir()
        shutil.copy(town["graph"], tmp_path / name / "graph" / "graph.graphml")
        shutil.copy(town["osm"], tmp_path / name / "osm" / "region.osm")
        maps[name] = tmp_path / name
    out = tmp_path / "bench.md"
    args = ["--map", f"one={maps['one']}", "--map", f"two={maps['two']}", "--case", "one:two", "--seeds", "0",
                 "--workers", "1", "--work", str(tmp_path / "work"), "--out", str(out), "--set",
                 "render.length_m=160", "drive.demonstrations.routes=3", "drive.demonstrations.val_routes=1",
                 "drive.demonstrations.route_length_m=150", "drive.demonstrations.min_distance_m=0",
                 "drive.train.max_epochs=1", "drive.train.batches_per_epoch=2", "drive.check.routes=2"]
    assert main(args) == 0
    text = out.read_text()
    assert "| one:two" in text and "2 check routes of 150 m per case" in text
    junctions = pd.read_csv(tmp_path / "bench.junctions.csv")
    assert set(junctions.case) == {"one:two"} and set(junctions.result) <= {TAKEN, FAILED, NOT_REACHED}
    assert len(list((tmp_path / "work").glob("controller_one-two_0_*.ckpt"))) == 1
    assert len(list((tmp_path / "work").glob("demonstrations_one_*.npz"))) == 1
    assert not list((tmp_path / "work").glob("demonstrations_two_*.npz"))  # the checked map is never trained on
    controller = next((tmp_path / "work").glob("controller_one-two_0_*.ckpt"))
    trained = controller.stat().st_mtime_ns
    assert main(args) == 0  # again: the kept controller is checked, not trained again
    assert controller.stat().st_mtime_ns == trained
    with pytest.raises(SystemExit):  # a case naming a map not given
        main(["--map", f"one={maps['one']}", "--case", "one:two"])
    # Taught and repeated: the kept controller drives each check route's teach map with each localization.
    retrieval = tmp_path / "retrieval.ckpt"
    net = SiameseNet(channels=[8, 16], embedding_dim=16, hidden=32)
    torch.save({"state_dict": net.state_dict(), "hyper_parameters": dict(net.hparams),
                "pytorch-lightning_version": L.__version__}, retrieval)
    with pytest.raises(SystemExit):  # no retrieval network for the maps
        main([*args, "--teach-repeat", "ground_truth"])
    assert main([*args, "--teach-repeat", "ground_truth,place_loop", "--retrieval", str(retrieval)]) == 0
    assert controller.stat().st_mtime_ns == trained
    text = out.read_text()
    assert "taught and repeated with ground_truth, place_loop" in text
    for name in ("ground_truth", "place_loop"):  # a row per seed, and one of the summary
        assert sum(line.startswith("| one:two") and f"| {name} " in line for line in text.splitlines()) == 2, text
    junctions = pd.read_csv(tmp_path / "bench.junctions.csv")
    assert set(junctions.localization) == {"ground_truth", "place_loop"}


def test_check_routes_are_drawn_in_a_range_of_lengths_the_same_on_every_map(town, tmp_path):  # noqa: F811 (the fixture)
    lengths = [check_length(r, 0, (300.0, 500.0)) for r in range(50)]
    assert all(300 <= x <= 500 for x in lengths) and max(lengths) - min(lengths) > 100
    assert lengths == [check_length(r, 0, (300.0, 500.0)) for r in range(50)]  # drawn again: the same
    assert check_length(3, 0, (150.0, 150.0)) == 150.0
    for name in ("one", "two"):
        (tmp_path / name / "graph").mkdir(parents=True)
        (tmp_path / name / "osm").mkdir()
        shutil.copy(town["graph"], tmp_path / name / "graph" / "graph.graphml")
        shutil.copy(town["osm"], tmp_path / name / "osm" / "region.osm")
    conf = load(REPO / "config" / "config.yaml", dotted_overrides(["render.length_m=160"]))
    threads = torch.get_num_threads()
    try:
        _init_worker(conf, {n: str(tmp_path / n) for n in ("one", "two")}, None, (120.0, 180.0))
        made = {n: [_check_routes(n, r).length_m for r in range(6)] for n in ("one", "two")}
        _init_worker(conf, {"one": str(tmp_path / "one")})
        default = _check_routes("one", 0).length_m
    finally:
        torch.set_num_threads(threads)
    assert made["one"] == made["two"] and all(120 <= x <= 180 for x in made["one"]) and len(set(made["one"])) > 1
    assert default == conf["drive"]["demonstrations"]["route_length_m"]
    for bad in ("300,200", "300,400,500", "300,x"):  # MIN above MAX, three lengths, not a number
        with pytest.raises(SystemExit):
            main(["--map", f"one={tmp_path / 'one'}", "--case", "one:one", "--route-length-m", bad])
