"""The simulated and city experiments on a synthetic grid map: one level's job, and the summary over levels."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tests.conftest import make_config
from topoloc.errors import InputError
from topoloc.experiments import city, simulated
from topoloc.experiments.many_starts import targets
from topoloc.localization import calibration
from topoloc.experiments.maps import grid_osm


def _conf(**experiment):
    config = make_config(experiments=experiment)
    return {k: config[k] for k in ("localization", "segmentation", "encoding", "graph")}, config["experiments"]


def test_grid_map_is_the_same_for_the_same_seed(tmp_path):
    first = grid_osm(tmp_path / "a.osm").read_text()
    assert first == grid_osm(tmp_path / "b.osm").read_text()
    assert first != grid_osm(tmp_path / "c.osm", seed=1).read_text()
    assert first.count("<node ") == 63 and first.count("<way ") == 16


def test_drive_plan_random_drives_then_a_circuit_and_a_stop_and_reverse():
    plan = simulated.drive_plan(2, np.random.default_rng([0, 0, 0]))
    assert [p for p, _ in plan] == ["random", "random", "circuit", "stop_reverse"]
    assert all(500.0 <= length <= 4000.0 for _, length in plan[:2]) and plan[2:] == [("circuit", 1600.0), ("stop_reverse", 1500.0)]


@pytest.fixture(scope="module")
def simulated_levels(tmp_path_factory):
    """Both levels' jobs of the simulated experiment on the grid map: hmm from a start every 400 m, one random drive
    (the oracle resolves none of the starts of the circuit and the stop-and-reverse drive at level low, so without
    it the localized share is undefined)."""
    tmp = tmp_path_factory.mktemp("simulated")
    base, experiments = _conf(simulated={"maps": ["grid"], "levels": ["low", "medium"], "drives": 1,
                                         "localizers": ["hmm"], "start_every_m": 400.0})
    inputs = {}
    for level in ("low", "medium"):
        outputs = {k: str(tmp / level / f"{k}.{ext}") for k, ext in (("starts", "csv"), ("figures", "md"), ("metrics", "json"))}
        simulated.run({**base, "simulated": experiments["simulated"], "level": level}, {}, outputs)
        inputs[f"starts_{level}"] = outputs["starts"]
    return tmp, experiments, inputs


def test_simulated_level_job(simulated_levels):
    tmp, _, inputs = simulated_levels
    frame = pd.read_csv(inputs["starts_low"])
    assert set(frame.level) == {"low"} and set(frame["map"]) == {"grid"} and set(frame.localizer) == {"hmm"}
    assert list(dict.fromkeys(frame.drive)) == ["grid/low/00-random", "grid/low/01-circuit", "grid/low/02-stop_reverse"]
    assert (frame.groupby("drive").start_m.min() == 0).all()
    assert frame.groupby("drive").start_m.diff().dropna().between(395.0, 405.0).all()  # a start every 400 m
    metrics = json.loads((tmp / "low" / "metrics.json").read_text())
    assert metrics["hmm/starts"] == len(frame)
    assert metrics["hmm/localized_share"] == pytest.approx(targets(frame)["localized_share"])
    assert 0.0 <= metrics["hmm/ece"] <= 1.0 and metrics["hmm/ece"] == pytest.approx(targets(frame)["ece"])  # every experiment's
    figures = (tmp / "low" / "figures.md").read_text()
    assert "## Per map and noise level" in figures and "## Overall" in figures and "hmm" in figures
    # the medium level's drives are other draws (the level's place in the list seeds them)
    assert not pd.read_csv(inputs["starts_medium"])[["start_m"]].equals(frame[["start_m"]])


def test_simulated_summary_mean_and_spread_over_levels(simulated_levels):
    tmp, experiments, inputs = simulated_levels
    outputs = {"summary": str(tmp / "summary.md"), "json": str(tmp / "summary.json"),
               "reliability": str(tmp / "reliability.png")}
    metrics = simulated.summarize({"simulated": experiments["simulated"]}, inputs, outputs)
    frames = [pd.read_csv(inputs[f"starts_{lv}"]) for lv in ("low", "medium")]
    shares = [targets(frame)["localized_share"] for frame in frames]
    # calibration over both levels' answers pooled: the figure and its ECE, not the mean of the levels' ECEs
    assert metrics["hmm/ece_all_levels"] == pytest.approx(calibration.ece(pd.concat(frames)))
    assert metrics["hmm/ece_all_levels"] != pytest.approx(metrics["hmm/ece_mean"])
    assert (tmp / "reliability.png").stat().st_size > 10_000
    text = (tmp / "summary.md").read_text()
    assert text.startswith("## Simulated drives: localizers against the oracle\n\nLocalizers beside the oracle")
    assert f"{np.mean(shares):.3f} ± {np.std(shares, ddof=1):.3f}" in text
    data = json.loads((tmp / "summary.json").read_text())
    assert data["groups"][0]["localizer"] == "hmm" and data["groups"][0]["level"] == ["low", "medium"]
    assert data["groups"][0]["mean"]["localized_share"] == pytest.approx(np.mean(shares))


def test_city_level_job_and_summary(tmp_path):
    osm = grid_osm(tmp_path / "grid.osm")
    base, experiments = _conf(city={"maps": ["grid"], "osm": {"grid": str(osm)}, "levels": ["low"], "drives": 1,
                                    "start_every_m": 1500.0})
    conf = {**base, "city": experiments["city"], "level": "low"}
    outputs = {k: str(tmp_path / "low" / f"{k}.{ext}")
               for k, ext in (("starts", "csv"), ("speed", "csv"), ("figures", "md"), ("metrics", "json"))}
    metrics = city.run(conf, {}, outputs)
    starts, speed = pd.read_csv(outputs["starts"]), pd.read_csv(outputs["speed"])
    assert set(starts.localizer) == {"metric"} and set(starts.drive) == {"grid/low/00"}
    assert list(speed.level) == ["low", "oracle"]  # one drive timed live, then the map's oracle row
    drive, cell_m = speed.iloc[0], base["localization"]["metric"]["cell_m"]
    assert 3000.0 <= drive.length_m <= 10000.0 * 1.01
    assert 0.9 * drive.length_m / cell_m <= drive.steps <= 1.1 * drive.length_m / cell_m  # one step per cell_m driven
    assert 50.0 < drive.peak_mb < 100_000.0  # megabytes (ru_maxrss is in kB)
    assert metrics["peak_mb"] == pytest.approx(speed.peak_mb.max())
    assert metrics["localized_share"] == pytest.approx(targets(starts)["localized_share"])
    assert "## Speed" in (tmp_path / "low" / "figures.md").read_text()
    summary = {"summary": str(tmp_path / "summary.md"), "json": str(tmp_path / "summary.json")}
    city.summarize({"city": experiments["city"]}, {"metrics_low": outputs["metrics"]}, summary)
    text = (tmp_path / "summary.md").read_text()
    assert text.startswith("## City-scale maps")
    assert text.splitlines()[-1].split("|")[-2].strip() == f"{metrics['peak_mb']:.3f}"  # the last column: peak MB
    assert "mean ± sd" not in text  # one level: nothing to average


def test_city_map_without_a_file_is_one_line_naming_the_key(tmp_path):
    base, experiments = _conf(city={"maps": ["nowhere"], "osm": {"nowhere": str(tmp_path / "no.osm.pbf")}})
    with pytest.raises(InputError, match=r"^experiments.city.osm.nowhere: no OSM file at .*no.osm.pbf$"):
        city.localize_level({**base, "city": experiments["city"]}, "low", None)


def test_city_starts_localized_in_banks_of_any_size_give_the_same_answers(tmp_path):
    osm = grid_osm(tmp_path / "grid.osm")
    tables = []
    for bank in (1, 10):
        base, experiments = _conf(city={"maps": ["grid"], "osm": {"grid": str(osm)}, "levels": ["low"], "drives": 1,
                                        "start_every_m": 1000.0, "live_drives": 0, "starts_per_bank": bank})
        frame, _ = city.localize_level({**base, "city": experiments["city"]}, "low", None)
        tables.append(frame)
    assert len(tables[0]) >= 3  # several starts, so a bank of one splits them
    # where each start localizes and how its answers score; confidences differ in float32's last digits (a bank's
    # sums run in another order), which can move an answer across a calibration bin or between two equal places:
    # a step or two of a start (one step of 578 with U-turns at 0.3 and across a median)
    same = ["start", "steps", "localized_m"]
    pd.testing.assert_frame_equal(tables[0][same], tables[1][same])
    for column in ("accuracy_after", "confident_wrong"):
        a, b = tables[0][column].to_numpy(), tables[1][column].to_numpy()
        assert (np.isnan(a) == np.isnan(b)).all(), column
        assert (np.nan_to_num(np.abs(a - b)) <= 2.0 / tables[0].steps.to_numpy()).all(), (column, a, b)
    np.testing.assert_allclose(tables[0].position_error_m, tables[1].position_error_m, atol=0.01)
