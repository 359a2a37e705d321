"""The seed table of benchmarks/drive_seeds.py, and its one-line errors on missing pipeline outputs."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from tests.conftest import make_config

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "drive_seeds.py"


@pytest.fixture(scope="module")
def drive_seeds():
    spec = importlib.util.spec_from_file_location("drive_seeds", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_table_rows_per_seed_and_their_mean(drive_seeds) -> None:
    rows = [{"seed": 0, "checks": {"helsinki": 0.6, "kitti00": 0.8},
             "follow": {"lp_place_loop_success_mean": 0.9, "lp_place_loop_success_min": 0.8,
                        "lp_place_loop_success_fog": 0.8, "lp_place_loop_success_night": 1.0}},
            {"seed": 3, "checks": {"helsinki": 0.7, "kitti00": 0.9},
             "follow": {"lp_place_loop_success_mean": 0.5, "lp_place_loop_success_min": 0.2,
                        "lp_place_loop_success_fog": 0.8, "lp_place_loop_success_night": 0.2}}]
    lines = drive_seeds.table(rows, "lp", ["place_loop"], ["mean", "min", "fog", "night"]).splitlines()
    assert lines[0] == "| seed | check helsinki | check kitti00 | place_loop mean | place_loop min | place_loop fog | place_loop night |"
    assert lines[2] == "| 0 | 0.60 | 0.80 | 0.90 | 0.80 | 0.80 | 1.00 |"
    assert lines[3] == "| 3 | 0.70 | 0.90 | 0.50 | 0.20 | 0.80 | 0.20 |"
    assert lines[4] == "| **mean** | **0.65** | **0.85** | **0.70** | **0.50** | **0.80** | **0.60** |"


def test_missing_pipeline_output_is_one_line_naming_it(drive_seeds, tmp_path, monkeypatch) -> None:
    conf = make_config(region={"name": "town", "osm_file": "town.osm"})  # download_osm writes it as region.osm
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match=r"results/town/osm/region.osm: missing \(made by the rule download_osm"):
        drive_seeds.osm_input(conf)
    (tmp_path / "results" / "town" / "osm").mkdir(parents=True)
    (tmp_path / "results" / "town" / "osm" / "region.osm").write_text("<osm/>")
    assert drive_seeds.osm_input(conf) == "results/town/osm/region.osm"
    with pytest.raises(SystemExit, match=r"map.npz: missing \(made by the rule build_topometric_map"):
        drive_seeds.require(tmp_path / "map.npz", "build_topometric_map")
    with pytest.raises(SystemExit, match=r"wide/demos.npz: missing \(made by the rule simulate_demonstrations"):
        drive_seeds.train_seed(conf, "lp", 0, tmp_path / "out", tmp_path / "wide" / "demos.npz")
