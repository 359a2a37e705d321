"""Calibration of the confidence: reliability diagrams and the expected calibration error (ECE), from answers or from
the per-start bin sums of the evaluation."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from localization_helpers import corridor_graph

from topoloc.localization import calibration
from topoloc.localization.evaluate_localization import reliability_lines
from topoloc.localization.evaluation import DriveTruth, Judge, score_start, summarize


def synthetic(rng, n, honest=True):
    """``n`` answers with confidences uniform on [0, 1]; right with probability the confidence (``honest``) or with
    a third of it (overconfident)."""
    confidence = rng.uniform(0.0, 1.0, n)
    right = rng.uniform(0.0, 1.0, n) < (confidence if honest else confidence / 3.0)
    return confidence, right


def test_ece_of_a_calibrated_set_is_near_zero_and_of_an_overconfident_one_large():
    rng = np.random.default_rng(0)
    assert calibration.expected_calibration_error(*synthetic(rng, 100_000)) < 0.01
    over = calibration.expected_calibration_error(*synthetic(rng, 100_000, honest=False))
    assert over == pytest.approx(0.5 * 2 / 3, abs=0.01)  # mean gap: E[c - c / 3] with c uniform
    # always sure, right half the time: the gap is 0.5 in the top bin
    assert calibration.expected_calibration_error(np.ones(1000), np.arange(1000) % 2 == 0) == pytest.approx(0.5)
    assert np.isnan(calibration.expected_calibration_error([], []))


def test_reliability_bins_count_and_share():
    confidence = np.array([0.05, 0.05, 0.55, 0.95, 1.0, 0.91])
    right = np.array([False, True, True, True, False, True])
    table = calibration.reliability(calibration.bin_sums(confidence, right))
    assert table.answers.tolist() == [2, 0, 0, 0, 0, 1, 0, 0, 0, 3]
    assert table.share_right[0] == 0.5 and table.share_right[5] == 1.0 and table.share_right[9] == pytest.approx(2 / 3)
    assert table.confidence[9] == pytest.approx((0.95 + 1.0 + 0.91) / 3) and np.isnan(table.share_right[1])
    with pytest.raises(ValueError):
        calibration.bin_sums([0.5], [True, False])


def test_bin_sums_of_starts_add_up_to_the_pooled_answers():
    rng = np.random.default_rng(1)
    confidence, right = synthetic(rng, 3000, honest=False)
    rows = pd.DataFrame([calibration.bin_sums(confidence[i:i + 1000], right[i:i + 1000]) for i in (0, 1000, 2000)])
    assert calibration.ece(rows) == pytest.approx(calibration.expected_calibration_error(confidence, right))
    assert calibration.reliability(rows).answers.sum() == 3000


def test_reliability_per_localizer_pools_its_starts_and_leaves_out_the_named_ones():
    rng = np.random.default_rng(2)
    rows = []
    for name, honest in (("honest", True), ("over", False), ("honest", True), ("oracle", True)):
        rows.append({"localizer": name, **calibration.bin_sums(*synthetic(rng, 2000, honest))})
    frame = pd.DataFrame(rows)
    diagrams = calibration.reliability_per(frame, skip=["oracle"])
    assert list(diagrams) == ["honest", "over"]
    assert diagrams["honest"].answers.sum() == 4000 and diagrams["over"].answers.sum() == 2000
    # the overconfident one is right a third as often as it says in its top bin
    assert diagrams["over"].share_right[9] == pytest.approx(diagrams["over"].confidence[9] / 3, abs=0.05)
    assert diagrams["honest"].share_right[9] == pytest.approx(diagrams["honest"].confidence[9], abs=0.05)


def test_the_evaluation_scores_calibration_with_the_judge():
    graph = corridor_graph()
    x = np.arange(0.0, 300.0)
    truth = DriveTruth(np.minimum(x // 100, 2).astype(np.int64), np.column_stack([x, np.zeros_like(x)]), x.copy())
    frames = np.arange(5, 300, 10)  # 30 answers: road 4 (wrong) with 0.95 before 150 m, then the truth with 0.95
    state = np.where(frames < 150, 4, truth.edge[frames])
    m = score_start(Judge(graph, 5.0), truth, 0, frames, state, np.full(len(frames), 0.95), None, 100.0, 0.9)
    assert m["cal_n_9"] == 30 and m["cal_right_9"] == 15 and m["cal_conf_9"] == pytest.approx(28.5)
    assert calibration.ece(m) == pytest.approx(0.45)
    # the oracle's rows carry no answers: NaN, not 0
    table = pd.DataFrame([{"drive": "d", "localizer": "x", **m, "oracle_m": 50.0, "ratio": 1.0},
                          {"drive": "d", "localizer": "oracle", "steps": 1.0, "localized_m": 50.0, "accuracy_after": np.nan,
                           "position_error_m": np.nan, "confident_wrong": np.nan, "oracle_m": 50.0, "ratio": 1.0}])
    summary = summarize(table).set_index(["drive", "localizer"])
    assert summary.loc[("all", "x"), "ece"] == pytest.approx(0.45) and np.isnan(summary.loc[("all", "oracle"), "ece"])
    lines = reliability_lines(table)
    assert lines[0] == "## Calibration" and lines[-1].startswith("| x | 0.450 |") and lines[-1].endswith("| 0.50 (30) |")


def test_logit_calibration_is_monotone_keeps_the_ends_and_the_identity():
    c = np.array([0.0, 1e-9, 0.2, 0.5, 0.9, 0.99, 1.0])
    assert np.array_equal(calibration.LogitCalibration().array(c), c)
    cool = calibration.LogitCalibration(0.8, -0.1)
    out = cool.array(c)
    assert out[0] == 0.0 and out[-1] == 1.0 and (np.diff(out) > 0).all()
    assert out[4] < 0.9 and out[5] < 0.99  # a temperature above 1 pulls confidences towards a half
    assert [cool(float(v)) for v in c] == pytest.approx(out.tolist())
    assert cool(0.5) == pytest.approx(1.0 / (1.0 + np.exp(0.1)))  # logit 0 -> the shift alone
    with pytest.raises(ValueError, match="scale"):
        calibration.LogitCalibration(0.0)


def test_a_fitted_logit_calibration_undoes_an_overconfidence_it_was_fitted_on():
    rng = np.random.default_rng(1)
    truth = rng.uniform(-4, 4, 200_000)  # the true log-odds of each answer being right
    right = rng.uniform(size=truth.size) < 1.0 / (1.0 + np.exp(-truth))
    stated = 1.0 / (1.0 + np.exp(-(1.5 * truth + 0.3)))  # overconfident by a factor of 1.5 on the log-odds, and biased
    fitted = calibration.fit_logit_calibration(stated, right)
    assert fitted.scale == pytest.approx(1 / 1.5, rel=0.03) and fitted.shift == pytest.approx(-0.3 / 1.5, abs=0.03)
    before = calibration.expected_calibration_error(stated, right)
    after = calibration.expected_calibration_error(fitted.array(stated), right)
    assert before > 0.03 and after < 0.01
    honest = calibration.fit_logit_calibration(1.0 / (1.0 + np.exp(-truth)), right)
    assert honest.scale == pytest.approx(1.0, abs=0.03) and honest.shift == pytest.approx(0.0, abs=0.03)
