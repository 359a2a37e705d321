"""The map-error experiment on the synthetic maps: one error type's job, and the summary over the jobs."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tests.conftest import make_config
from topoloc.errors import InputError
from topoloc.experiments import map_error_starts, map_errors
from topoloc.experiments.many_starts import targets
from topoloc.localization import calibration


def _conf(error, **experiment):
    config = make_config(experiments={"map_errors": experiment})
    return {**{k: config[k] for k in ("localization", "segmentation", "encoding", "graph")},
            "map_errors": config["experiments"]["map_errors"], "error": error}


@pytest.fixture(scope="module")
def jobs(tmp_path_factory):
    """The jobs `none` and `missing_road` (level medium) on dual_grid and grid (with one random drive, which the
    oracle resolves): hmm from a start every 300 m."""
    tmp = tmp_path_factory.mktemp("map_errors")
    inputs = {}
    for error in ("none", "missing_road"):
        conf = _conf(error, maps=["dual_grid", "grid"], levels=["medium"], drives=1, localizers=["hmm"],
                     start_every_m=300.0)
        outputs = {k: str(tmp / error / f"{k}.{ext}") for k, ext in (("starts", "csv"), ("figures", "md"), ("metrics", "json"))}
        map_errors.run(conf, {}, outputs)
        inputs[f"starts_{error}"] = outputs["starts"]
    return tmp, inputs


def test_a_job_per_error_type(jobs):
    tmp, inputs = jobs
    frame = pd.read_csv(inputs["starts_missing_road"])
    assert set(frame.error) == {"missing_road"} and set(frame.level) == {"medium"} and set(frame.localizer) == {"hmm"}
    drives = list(dict.fromkeys(frame.drive))
    assert drives[:2] == ["dual_grid/missing_road/medium/00-out_and_back", "dual_grid/missing_road/medium/01-out_and_back"]
    assert {d.split("-", 1)[1] for d in drives[2:]} <= {"random", "out_and_back", "circle_block", "long_straight"}
    assert (frame.groupby("drive").start_m.min() == 0).all()
    assert set(pd.read_csv(inputs["starts_none"]).level) == {"none"}
    metrics = json.loads((tmp / "missing_road" / "metrics.json").read_text())
    assert metrics["medium/hmm/starts"] == len(frame)
    assert metrics["medium/hmm/oracle_resolved"] == pytest.approx(np.isfinite(frame.oracle_m).mean())
    # the share is defined where the oracle resolves starts: the random drive has some
    assert np.isfinite(frame.oracle_m).any()
    assert metrics["medium/hmm/localized_share"] == pytest.approx(targets(frame)["localized_share"])
    figures = (tmp / "missing_road" / "figures.md").read_text()
    assert "## Per error type and level" in figures and "## Per drive pattern" in figures


def test_the_mirror_walk_is_not_resolved_by_the_oracle(jobs):
    _, inputs = jobs
    frame = pd.read_csv(inputs["starts_none"])
    mirror = frame[frame["map"] == "dual_grid"]
    assert len(mirror) > 5 and not np.isfinite(mirror.oracle_m).any()


def test_summary_per_error_type_and_level(jobs):
    tmp, inputs = jobs
    outputs = {"summary": str(tmp / "summary.md"), "json": str(tmp / "summary.json"),
               "reliability": str(tmp / "reliability.png")}
    conf = _conf("none", maps=["dual_grid", "grid"], levels=["medium"], drives=1, localizers=["hmm"])
    metrics = map_errors.summarize({"map_errors": conf["map_errors"], "confirm_m": 200.0}, inputs, outputs)
    text = (tmp / "summary.md").read_text()
    assert text.startswith("## Map errors: localizers against the oracle of the map they see")
    assert "missing_road/medium" in text and "none/none" in text
    data = json.loads((tmp / "summary.json").read_text())
    assert {j["job"] for j in data["jobs"]} == {"none/none", "missing_road/medium"}
    frame = pd.read_csv(inputs["starts_missing_road"])
    job = next(j for j in data["jobs"] if j["job"] == "missing_road/medium")
    assert job["oracle_resolved"] == pytest.approx(np.isfinite(frame.oracle_m).mean())
    # calibration: the ECE of each job's answers in the summary, and of every job's pooled in the metrics and figure
    assert job["ece"] == pytest.approx(calibration.ece(frame))
    assert next(line for line in text.splitlines() if line.startswith("| localizer")).rstrip(" |").endswith("ece")
    pooled = pd.concat([pd.read_csv(inputs[k]) for k in sorted(inputs)])
    assert metrics["hmm/up_to_medium/ece"] == pytest.approx(calibration.ece(pooled))
    assert metrics["hmm/up_to_medium/ece"] != pytest.approx(job["ece"])  # both jobs' answers, not one's
    assert (tmp / "reliability.png").stat().st_size > 10_000
    # the targets are per level: each level's figures over every error type pooled
    medium = pooled[pooled.level == "medium"]
    assert metrics["hmm/all_errors/medium/oracle_resolved"] == pytest.approx(np.isfinite(medium.oracle_m).mean())
    assert metrics["hmm/all_errors/medium/localized_share"] == pytest.approx(targets(medium)["localized_share"])


def test_level_table_pools_every_error_type_and_counts_the_confirmed_starts():
    # two error types at one level: 4 resolved starts, 2 localized; the one localized with 100 m of drive after the
    # oracle's limit and the one missed with 50 m are not confirmed (200 m)
    frame = pd.DataFrame({"error": ["a", "a", "b", "b", "b", "none"], "level": ["medium"] * 5 + ["none"],
                          "localizer": ["x"] * 6, "oracle_m": [100.0, 100.0, 100.0, np.nan, 100.0, 50.0],
                          "length_m": [400.0, 200.0, 400.0, 400.0, 150.0, 300.0],
                          "localized_m": [120.0, 150.0, np.nan, np.nan, np.nan, 40.0],
                          "ratio": [1.2, 1.5, np.inf, np.nan, np.inf, 0.8], "steps": [10.0] * 6,
                          "accuracy_after": [1.0] * 6, "position_error_m": [1.0] * 6, "confident_wrong": [0.0] * 6})
    table = map_error_starts.level_table(frame, 200.0).set_index("level")
    assert table.loc["medium", "starts"] == 5 and table.loc["medium", "oracle_resolved"] == pytest.approx(0.8)
    assert table.loc["medium", "localized_share"] == pytest.approx(2 / 4)
    assert table.loc["medium", "confirmed"] == 2 and table.loc["medium", "localized_confirmed"] == pytest.approx(1 / 2)
    assert table.loc["none", "confirmed"] == 1 and table.loc["none", "localized_confirmed"] == 1.0


def test_unknown_map_is_one_clear_error(tmp_path):
    conf = _conf("none", maps=["atlantis"])
    with pytest.raises(InputError, match="experiments.map_errors.maps"):
        map_error_starts.load_base("atlantis", conf, {}, tmp_path)


def test_every_answer_of_a_job_for_a_recalibration(tmp_path):
    """``localize_error(..., answers=[])`` hands every answer over (its confidence and whether it is right), one frame
    per start that agrees with the start's bin sums; ``benchmarks.bench_recalibration`` fits on them."""
    conf = _conf("none", maps=["dual_grid"], levels=["medium"], drives=0, localizers=["metric"], start_every_m=1000.0)
    answers: list[pd.DataFrame] = []
    frame, _ = map_error_starts.localize_error(conf, "none", ["none"], {}, tmp_path, progress=False, answers=answers)
    assert len(answers) == len(frame) > 0
    for (_, row), given in zip(frame.iterrows(), answers):
        assert given.start.iloc[0] == row.start and set(given.localizer) == {"metric"} and set(given["map"]) == {"dual_grid"}
        sums = calibration.bin_sums(given.confidence, given.right)
        assert all(sums[k] == pytest.approx(row[k]) for k in calibration.COLUMNS)


def test_the_recalibration_benchmark_fits_and_checks(tmp_path):
    from benchmarks import bench_recalibration

    out = tmp_path / "recalibration.md"
    assert bench_recalibration.main(["--results", str(tmp_path / "none"), "--maps", "dual_grid", "--errors", "none",
                                     "--start-every", "1000", "--out", str(out)]) == 0
    text = out.read_text()
    assert "`localization.metric.confidence_scale: " in text
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines() if line.startswith("| fit") or line.startswith("| check")]
    table = {(r[0], r[2]): r[3:] for r in rows}  # (seeds, confidence) -> answers, ece, confident wrong, sure
    assert {k[0] for k in table} == {"fit (0)", "check (1)"}
    for seeds in ("fit (0)", "check (1)"):
        # the configured recalibration is the default, off: the same figures as the raw confidence
        assert table[(seeds, "configured")] == table[(seeds, "raw")]
        assert table[(seeds, "fitted")][0] == table[(seeds, "raw")][0] != "0"


def test_the_map_error_benchmark_pools_draws_and_shows_each(tmp_path):
    from benchmarks import bench_map_errors

    out = tmp_path / "map_errors.md"
    assert bench_map_errors.main(["--results", str(tmp_path / "none"), "--maps", "dual_grid", "--errors", "none",
                                  "--localizers", "metric", "--start-every", "1000", "--seeds", "0,1",
                                  "--starts", str(tmp_path / "starts.csv"), "--out", str(out)]) == 0
    text = out.read_text()
    assert "draws 0, 1" in text.splitlines()[0]
    per_draw = text.split("## Pooled per level, each draw")[1].split("##")[0]
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in per_draw.splitlines() if line.startswith("|")]
    header, body = rows[0], rows[2:]
    assert header[:3] == ["draw", "level", "localizer"] and [r[0] for r in body] == ["0", "1"]
    starts = pd.read_csv(tmp_path / "starts.csv")
    # each draw's row counts that draw's starts, and the draws differ (other lanes and odometry noise)
    assert [int(r[header.index("starts")]) for r in body] == [int((starts.draw == d).sum()) for d in (0, 1)]
    assert body[0][header.index("ece")] != body[1][header.index("ece")]

