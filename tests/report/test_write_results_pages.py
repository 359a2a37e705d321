"""The results pages and headline tables, made from tiny stage tables; the README's tables refreshed from them."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from topoloc.errors import InputError
from topoloc.report.markdown import blocks, demote, refresh, tables
from topoloc.report.write_results_pages import TASKS, _worst, run

LOCALIZATION = """# Localization on tiny

From a start every 100 m.

| drive | localizer | starts | localized | median (m) | p90 (m) | median ratio to oracle | acc. after | position error (m) | confident wrong |
|---|---|---|---|---|---|---|---|---|---|
| d1 | metric filter | 4 | 75.0 % | 150 | 300 | 0.80 | 0.990 | 2.10 | 0.0 % |
| **all** | oracle (uniqueness limit of the map) | 4 | 50.0 % | 200 | never | 1 |  |  |  |
| **all** | metric filter | 4 | 75.0 % | 150 | 300 | 0.80 | 0.990 | 2.10 | 0.0 % |

## From frame 0

| drive | localizer | updates |
|---|---|---|
| d1 | metric filter | 12 |
"""
PAPER = """# Teach-and-repeat localization (teach: clear_noon; held out of training: fog)

## {title}

| {first} | Mean | overcast | fog (held out) |
|---|---|---|---|
| {a} | 0.750 | 1.000 | 0.500 |
| {b} | 0.250 | 0.000 | 0.500 |

## Median localization error (m)

| {first} | Mean | overcast | fog (held out) |
|---|---|---|---|
| {a} | 1.00 | 1.00 | 1.00 |
"""


@pytest.fixture
def stage(tmp_path: Path):
    """Tiny inputs of every task, one benchmark report and one experiment summary; the conf and outputs."""
    files = {
        "localization": LOCALIZATION,
        "evaluation": json.dumps({"heldout_acc_last": 0.8125, "heldout_acc_500m": 0.5, "heldout_trajectories": 16,
                                  "train_seconds": 42.4}),
        "accuracy": "# Accuracy at the i-th position (tiny)\n\n| position | accuracy held-out |\n|---|---|\n| 1 | 0.5 |\n",
        "dataset": "# Table I: dataset statistics (tiny)\n\n| Data | Statistics |\n|---|---|\n| All Trajectories | 20 |\n",
        "teach_repeat": PAPER.format(title="Share of repeat frames localized within 5 m", first="method",
                                     a="siamese network + filter", b="odometry only"),
        "follow": PAPER.format(title="Success rate", first="agent (localization)", a="Topo-LP (place_loop)",
                               b="replay (ground truth)"),
        "odometry_d1": json.dumps({"source": "rendered", "length_m": 994.26, "evaluation": {"t_err_pct": 0.4317,
                                   "r_err_deg_per_100m": 0.2269, "ate_m": 0.799}, "labels": {"within_5m": 1.0}}),
        "odometry_d2": json.dumps({"source": "kitti_poses", "length_m": 500.0}),
        "controller_lp": json.dumps({"check/routes": 10, "check/success_rate": 0.3, "check/share_driven": 0.61}),
        "graph_stats": json.dumps({"edges": 497, "road_km": 31.608}),
    }
    inputs = {}
    for name, text in files.items():
        inputs[name] = str(tmp_path / "in" / f"{name}.txt")
        Path(inputs[name]).parent.mkdir(exist_ok=True)
        Path(inputs[name]).write_text(text)
    bench, experiments, jobs = tmp_path / "benchmarks", tmp_path / "experiments", tmp_path / "jobs"
    (experiments / "rnn_ablation").mkdir(parents=True)
    bench.mkdir()
    jobs.mkdir()
    (bench / "bench_localization.md").write_text("# Localization benchmark\n\nmedian 205 m\n")
    (bench / "bench_something_new.md").write_text("# New\n\nfigure 7\n")
    (experiments / "rnn_ablation" / "summary.md").write_text("# RNN ablation\n\nLSTM 128 kept\n")
    os.utime(bench / "bench_localization.md", (0, 0))
    for job, seconds, rss in (("build_graph", 4.82, 359.62), ("train_rnn", 230.0, 1800.4)):
        (jobs / f"{job}.tsv").write_text(f"s\th:m:s\tmax_rss\tcpu_time\n{seconds}\t0:00:04\t{rss}\t4.49\n")
    conf = {"region": "tiny", "benchmarks_dir": str(bench), "experiments_dir": str(experiments), "stage_benchmarks_dir": str(jobs)}
    outputs = {task: str(tmp_path / "pages" / f"{task}.md") for task in TASKS} | {"headline": str(tmp_path / "pages" / "headline.md")}
    return conf, inputs, outputs


def test_pages_hold_the_headline_the_stage_tables_and_the_reports_found(stage):
    conf, inputs, outputs = stage
    metrics = run(conf, inputs, outputs)
    assert metrics == {"pages": 6.0, "reports_included": 3.0}
    headline = blocks(Path(outputs["headline"]).read_text())
    assert set(headline) == set(TASKS)
    localization = tables(headline["localization"])[0][1]
    assert localization[0][:3] == ["region", "localizer", "starts"]
    assert localization[1:] == [["tiny", "oracle (uniqueness limit of the map)", "4", "50.0 %", "200", "1", "", ""],
                                ["tiny", "metric filter", "4", "75.0 %", "150", "0.80", "0.990", "2.10"]]
    assert tables(headline["trajectory"])[0][1][1] == ["tiny", "16", "-", "0.500", "-", "-", "42"]
    assert tables(headline["odometry"])[0][1][1:] == [["tiny", "d1", "rendered", "0.99", "0.43", "0.227", "0.80", "100.0 %"],
                                                      ["tiny", "d2", "kitti_poses", "0.50", "-", "-", "-", "-"]]
    assert tables(headline["place"])[0][1][1:] == [["tiny", "siamese network + filter", "0.750", "fog (held out): 0.500"],
                                                   ["tiny", "odometry only", "0.250", "overcast: 0.000"]]
    assert tables(headline["route_following"])[0][1][1][:3] == ["tiny", "Topo-LP (place_loop)", "0.750"]
    assert tables(headline["pipeline"])[0][1][1] == ["tiny", "497", "31.6", "2", "3.9", "1800"]

    page = Path(outputs["localization"]).read_text()
    assert page.startswith("# Localization: tiny")
    assert "### Localization on tiny" in page and "#### From frame 0" in page  # the stage's table, two levels down
    assert "benchmarks/bench_localization.md` (modified 1970-01-01 00:00 UTC)" in page
    assert "#### Localization benchmark" in page
    assert "RNN ablation" in Path(outputs["trajectory"]).read_text()
    pipeline = Path(outputs["pipeline"]).read_text()
    assert "bench_something_new.md" in pipeline and "| train_rnn | 230 | 1800 | 4 |" in pipeline
    assert "| lp | 10 | 0.30 | 0.61 |" in Path(outputs["route_following"]).read_text()
    assert "None found when this page was made" in Path(outputs["place"]).read_text()


def test_a_table_without_its_columns_names_the_file(stage):
    conf, inputs, outputs = stage
    Path(inputs["localization"]).write_text("# Localization\n\n| drive | starts |\n|---|---|\n| **all** | 4 |\n")
    with pytest.raises(InputError, match="localization.txt: table without the column"):
        run(conf, inputs, outputs)


def test_the_readme_tables_are_refreshed_from_every_region(stage, tmp_path):
    conf, inputs, outputs = stage
    run(conf, inputs, outputs)
    other = Path(outputs["headline"]).read_text().replace("| tiny |", "| other |")
    readme = ("# Project\n\n<!-- headline:localization -->\nold table\n<!-- /headline:localization -->\n\ntext\n"
              "<!-- headline:cluster -->\nkept\n<!-- /headline:cluster -->\n")
    text, replaced = refresh(readme, [Path(outputs["headline"]).read_text(), other])
    assert replaced == ["localization"]
    rows = tables(blocks(text)["localization"])[0][1]
    assert [row[0] for row in rows] == ["region", "tiny", "tiny", "other", "other"]
    assert "old table" not in text and "\ntext\n" in text and "kept" in text


def test_demote_moves_every_heading_down():
    assert demote("# a\n## b\nnot # c\n", 2) == "### a\n#### b\nnot # c\n"


def test_the_worst_condition_is_the_first_of_equal_values():
    head = ["agent (localization)", "Mean", "overcast", "fog (held out)", "night"]
    assert _worst(["replay", "0.33", "0.00", "1.00", "0.00"], head) == "overcast: 0.00"
    assert _worst(["replay", "-", "-", "-", "-"], head) == "-"
