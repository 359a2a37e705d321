"""The drive_seeds experiment's aggregate: the seed table, and the summary from the seeds' training and follow metrics."""

from __future__ import annotations

import json

import pytest

from topoloc.experiments.drive_seeds import summarize, table

ROWS = [{"seed": 0, "checks": {"helsinki": 0.6, "kitti00": 0.8},
         "follow": {"lp_place_loop_success_mean": 0.9, "lp_place_loop_success_min": 0.8,
                    "lp_place_loop_success_fog": 0.8, "lp_place_loop_success_night": 1.0}},
        {"seed": 3, "checks": {"helsinki": 0.7, "kitti00": 0.9},
         "follow": {"lp_place_loop_success_mean": 0.5, "lp_place_loop_success_min": 0.2,
                    "lp_place_loop_success_fog": 0.8, "lp_place_loop_success_night": 0.2}}]


def test_table_rows_per_seed_their_mean_and_spread() -> None:
    lines = table(ROWS, "lp", ["place_loop"], ["mean", "min", "fog", "night"]).splitlines()
    assert lines[0] == "| seed | check helsinki | check kitti00 | place_loop mean | place_loop min | place_loop fog | place_loop night |"
    assert lines[2] == "| 0 | 0.60 | 0.80 | 0.90 | 0.80 | 0.80 | 1.00 |"
    assert lines[3] == "| 3 | 0.70 | 0.90 | 0.50 | 0.20 | 0.80 | 0.20 |"
    assert lines[4] == "| **mean** | **0.65** | **0.85** | **0.70** | **0.50** | **0.80** | **0.60** |"
    assert lines[5] == "| sd | 0.07 | 0.07 | 0.28 | 0.42 | 0.00 | 0.57 |"


def test_summary_from_the_seeds_metrics(tmp_path) -> None:
    inputs = {}
    for seed, check, mean, route0 in ((0, 0.6, 0.9, 1.0), (1, 0.8, 0.5, 0.0)):
        (tmp_path / f"train{seed}.json").write_text(json.dumps({"check/success_rate": check, "train/loss": 0.1}))
        (tmp_path / f"follow{seed}.json").write_text(json.dumps({
            "lp_place_loop_success_mean": mean, "lp_place_loop_success_min": mean - 0.1,
            "lp_place_loop_success_fog": mean, "lp_place_loop_success_route0": route0,
            "lp_place_loop_success_route1": 1.0}))
        inputs |= {f"train_{seed}": str(tmp_path / f"train{seed}.json"), f"follow_{seed}": str(tmp_path / f"follow{seed}.json")}
    conf = {"drive_seeds": {"agent": "lp", "seeds": [0, 1]}, "region": "town", "train_region": "city",
            "localization": ["place_loop"], "conditions": ["fog"]}
    outputs = {"summary": str(tmp_path / "summary.md"), "routes": str(tmp_path / "routes.md"),
               "json": str(tmp_path / "summary.json")}
    metrics = summarize(conf, inputs, outputs)
    summary = (tmp_path / "summary.md").read_text().splitlines()
    assert summary[0] == "## Route following over training seeds"
    assert "demonstrations of city, each checked on unseen routes there and driven alone on the teach route of town" in summary[2]
    assert "| seed | check city | place_loop mean | place_loop min | place_loop fog |" in summary
    assert "| **mean** | **0.70** | **0.70** | **0.60** | **0.70** |" in summary
    routes = (tmp_path / "routes.md").read_text()
    assert "| seed | check city | place_loop route0 | place_loop route1 |" in routes
    assert "| **mean** | **0.70** | **0.50** | **1.00** |" in routes
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["seeds"] == [0, 1] and data["mean"]["check/city"] == 0.7
    assert metrics["lp_place_loop_success_mean_mean"] == 0.7


def test_controllers_from_another_region_are_checked_here_too(tmp_path) -> None:
    inputs = {}
    for seed, home, here in ((0, 0.6, 0.8), (1, 0.7, 0.9)):
        for name, data in (("train", {"check/success_rate": home}), ("check", {"check/success_rate": here}),
                           ("follow", {"lp_place_loop_success_mean": 0.5})):
            (tmp_path / f"{name}{seed}.json").write_text(json.dumps(data))
            inputs[f"{name}_{seed}"] = str(tmp_path / f"{name}{seed}.json")
    conf = {"drive_seeds": {"agent": "lp", "seeds": [0, 1]}, "region": "kitti00", "train_region": "helsinki",
            "localization": ["place_loop"], "conditions": []}
    outputs = {k: str(tmp_path / f"{k}.out") for k in ("summary", "routes", "json")}
    summarize(conf, inputs, outputs)
    summary = (tmp_path / "summary.out").read_text()
    assert "| seed | check helsinki | check kitti00 | place_loop mean | place_loop min |" in summary
    assert "| **mean** | **0.65** | **0.85** | **0.50** | **nan** |" in summary
    assert json.loads((tmp_path / "json.out").read_text())["mean"]["check/kitti00"] == pytest.approx(0.85)
