"""The RNN ablation's variant names, its per-drive figures and its summary over the variants."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from topoloc.errors import InputError
from topoloc.experiments.rnn_ablation import drive_figures, parse_variant, summarize


def test_variants_name_cell_size_and_inputs():
    assert parse_variant("lstm-128") == ("lstm", 128, True)
    assert parse_variant("gru-64-tokens") == ("gru", 64, False)
    for bad in ("lstm", "lstm-x", "lstm-128-features"):
        with pytest.raises(InputError, match=r"^experiments.rnn_ablation.variants: "):
            parse_variant(bad)


def test_drive_figures_of_one_localizer():
    summary = pd.DataFrame([{"drive": d, "localizer": n, "localized_share": s, "median_m": m, "accuracy_after": a}
                            for d, n, s, m, a in (("gt", "hmm", 0.5, 300.0, 0.9), ("gt", "rnn_filter", 0.8, 200.0, 0.95),
                                                  ("orbslam2", "rnn_filter", 0.7, 250.0, 0.93))])
    assert drive_figures(summary, "rnn_filter", ["gt", "orbslam2"]) == {
        "gt_localized_share": 0.8, "gt_median_m": 200.0, "gt_accuracy_after": 0.95,
        "orbslam2_localized_share": 0.7, "orbslam2_median_m": 250.0, "orbslam2_accuracy_after": 0.93}


def test_summary_over_the_variants(tmp_path):
    rows = {"hmm": [{"variant": "hmm", "localizer": "hmm", "gt_localized_share": 0.5, "gt_median_m": 300.0},
                    {"variant": "oracle", "localizer": "oracle", "gt_localized_share": 1.0, "gt_median_m": 100.0}],
            "lstm-64": [{"variant": "lstm-64", "train_s": 10.0, "heldout_acc": 0.90, "localizer": "rnn_filter",
                         "gt_localized_share": 0.8, "gt_median_m": 200.0}],
            "gru-64": [{"variant": "gru-64", "train_s": 20.0, "heldout_acc": 0.94, "localizer": "rnn_filter",
                        "gt_localized_share": 0.6, "gt_median_m": 260.0}]}
    inputs = {}
    for name, table in rows.items():
        pd.DataFrame(table).to_csv(tmp_path / f"{name}.csv", index=False)
        inputs[f"rows_{name}"] = str(tmp_path / f"{name}.csv")
    conf = {"rnn_ablation": {"variants": ["lstm-64", "gru-64"], "localizers": ["rnn_filter"], "drives": ["gt"]}}
    outputs = {"summary": str(tmp_path / "summary.md"), "json": str(tmp_path / "summary.json")}
    metrics = summarize(conf, inputs, outputs)
    text = (tmp_path / "summary.md").read_text()
    assert text.startswith("## Trajectory RNN ablation\n\nThe trajectory RNN trained with each of lstm-64, gru-64")
    assert "0.920 ± 0.028" in text  # held-out accuracy of rnn_filter's two variants
    data = json.loads((tmp_path / "summary.json").read_text())
    rnn = next(g for g in data["groups"] if g["localizer"] == "rnn_filter")
    assert rnn["variant"] == ["lstm-64", "gru-64"] and rnn["mean"]["gt_median_m"] == pytest.approx(230.0)
    assert metrics == {"rnn_filter/heldout_acc_max": 0.94}
