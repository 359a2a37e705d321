"""End-to-end: the default pipeline, its caching, its MLflow runs and its errors."""

from __future__ import annotations

import json

import pandas as pd
import pytest

pytestmark = pytest.mark.slow

GRAPH_OUTPUTS = ["graph.graphml", "edges.csv", "nodes.csv", "virtual_segments.csv", "stats.json", "map.png"]


def mlflow_runs(root):
    from mlflow import MlflowClient

    client = MlflowClient(f"sqlite:///{root / 'results' / 'mlflow.db'}")
    experiment = client.get_experiment_by_name("topoloc")
    return client, client.search_runs([experiment.experiment_id])


def test_pipeline_caching_and_tracking(workflow):
    root = workflow.root
    jobs = workflow.planned("all")
    workflow.run("all", "-j", "4")
    graph_dir = root / "results" / "helsinki" / "graph"
    assert all((graph_dir / name).is_file() for name in GRAPH_OUTPUTS)
    stats = json.loads((graph_dir / "stats.json").read_text())
    assert stats["edges"] > 300 and stats["virtual_nodes"] > stats["edges"]
    for rule in ("download_osm", "build_graph"):
        assert (root / "results" / "helsinki" / "logs" / f"{rule}.log").is_file()
        assert (root / "results" / "helsinki" / "benchmarks" / f"{rule}.tsv").is_file()

    client, runs = mlflow_runs(root)
    parents = [r for r in runs if r.data.tags.get("topoloc.role") == "pipeline"]
    children = {r.data.tags["topoloc.rule"]: r for r in runs if "mlflow.parentRunId" in r.data.tags}
    assert len(parents) == 1 and parents[0].info.status == "FINISHED"
    child_runs = [r for r in runs if "mlflow.parentRunId" in r.data.tags]
    assert len(child_runs) == sum(jobs.values())  # one run per executed job
    assert set(children) == set(jobs) >= {"download_osm", "build_graph"}
    build = children["build_graph"]
    assert build.data.tags["mlflow.parentRunId"] == parents[0].info.run_id
    assert build.data.tags["topoloc.wildcards.region"] == "helsinki"
    assert len(build.data.tags["topoloc.input_sha256.osm"]) == 64
    assert build.data.tags["topoloc.git_commit"] and build.data.tags["topoloc.git_dirty"]
    assert build.data.params["virtual_node_spacing_m"] == "20"
    assert build.data.metrics["edges"] == stats["edges"]
    artifacts = {a.path for a in client.list_artifacts(build.info.run_id)}
    assert {"stats.json", "map.png", "logs"} <= artifacts

    # Localization: every localizer on every drive from every start beside the oracle, the tables, the CDF, Fig. 9,
    # the HTML report; one MLflow run each.
    loc = root / "results" / "helsinki" / "localization"
    table = (loc / "localization.md").read_text()
    assert all(name in table for name in ("raw (argmax)", "Strategy 1", "Strategy 2", "RNN + map filter", "HMM baseline", "metric filter",
                                          "oracle (uniqueness limit of the map)", "**all**", "From frame 0"))
    assert (loc / "fig9_ren00_clear_noon.png").stat().st_size > 10_000 and (loc / "localized_cdf.png").stat().st_size > 10_000
    assert (loc / "ren00_clear_noon" / "localization.geojson").is_file()
    answers = pd.read_csv(loc / "ren00_clear_noon" / "answers.csv")
    assert set(answers.localizer) == {"raw", "strategy1", "strategy2", "rnn_filter", "hmm", "metric"} and answers.start.nunique() >= 1
    starts = pd.read_csv(loc / "starts.csv")
    assert set(starts.localizer) == {"raw", "strategy1", "strategy2", "rnn_filter", "hmm", "metric", "oracle"}
    report = root / "results" / "helsinki" / "report.html"
    assert report.stat().st_size > 100_000 and b"fig9_ren00_clear_noon.png" in report.read_bytes()
    evaluate = children["evaluate_localization"]
    assert {"localization.md", "fig9_ren00_clear_noon.png"} <= {a.path for a in client.list_artifacts(evaluate.info.run_id)}
    assert {"metric_localized_share", "strategy1_localized_share", "oracle_localized_share"} <= set(evaluate.data.metrics)
    assert "report.html" in {
        a.path for a in client.list_artifacts(children["report_html"].info.run_id)}

    # Place recognition: per-condition tables, metrics per condition, the network logged as an MLflow model.
    teach_repeat = root / "results" / "helsinki" / "teach_repeat"
    assert "| method | Mean | overcast | sunset | rain | fog (held out) | night |" in (teach_repeat / "tables.md").read_text()
    assert {"network_within_5m_fog", "correlation_within_5m_night", "embed_images_per_s"} <= set(
        children["localize_repeat"].data.metrics)
    # (train/loss_step only once a run reaches log_every_n_steps: the tiny test training may stop before)
    assert {"val/acc_fog", "best/val/acc_fog", "best/epoch"} <= set(children["train_retrieval"].data.metrics)
    assert {"train/loss_step", "val/loss", "val/acc_last", "best/val/loss"} <= set(children["train_rnn"].data.metrics)
    import mlflow

    mlflow.set_tracking_uri(f"sqlite:///{root / 'results' / 'mlflow.db'}")
    models = mlflow.search_logged_models(experiment_ids=[children["train_retrieval"].info.experiment_id], output_format="list")
    assert any(m.source_run_id == children["train_retrieval"].info.run_id for m in models)

    # A second call finds everything up to date and records nothing.
    assert workflow.planned("all") == {}
    workflow.run("all", "--cores", "2")
    assert len(mlflow_runs(root)[1]) == len(runs)

    # A config key reruns the stages that use it (and, through their outputs, what depends on them).
    downstream = {rule: n for rule, n in jobs.items() if rule not in {"download_osm", "build_graph"}}
    spacing = workflow.config("spacing.yaml", "graph:\n  virtual_node_spacing_m: 25\n")
    assert workflow.planned("all", "--configfile", spacing) == {"build_graph": 1, **downstream}
    classes = workflow.config("classes.yaml", "graph:\n  highway_classes: [primary, secondary, residential]\n")
    assert workflow.planned("all", "--configfile", classes) == {"build_graph": 1, **downstream}
    retries = workflow.config("retries.yaml", "download:\n  retries: 5\n")
    assert workflow.planned("all", "--configfile", retries) == jobs

    # Editing a stage's library code reruns that stage, not the ones before it.
    plot = root / "src" / "topoloc" / "graph" / "plot.py"
    plot.write_text(plot.read_text() + "\n# edited\n")
    assert workflow.planned("all") == {"build_graph": 1, **downstream}
    plot.write_text(plot.read_text().replace("\n# edited\n", ""))
    assert workflow.planned("all") == {}

    # -R reruns the named stage (and what depends on it), not the ones before it.
    assert workflow.planned("all", "-R", "build_graph") == {"build_graph": 1, **downstream}


def test_bad_inputs_fail_with_one_line_and_leave_nothing(workflow):
    root = workflow.root
    (root / "corrupt.osm").write_text('<?xml version="1.0"?>\n<osm version="0.6">\n <way id="1"')
    corrupt = workflow.config("corrupt.yaml", "region:\n  name: broken\n  osm_file: corrupt.osm\n")
    proc = workflow.run("all", "--cores", "1", "--configfile", corrupt, check=False)
    assert proc.returncode != 0
    errors = [line for line in proc.stderr.splitlines() if line.startswith("topoloc: ")]
    assert len(errors) == 1 and errors[0].startswith("topoloc: corrupt.osm: cannot read OSM data (XML parsing error")
    assert errors[0].endswith("(region.osm_file)")
    assert proc.stderr.rstrip().splitlines()[-1] == errors[0]  # the last line the user sees, printed once
    assert not (root / "results" / "broken" / "osm" / "region.osm").exists()

    cases = {
        "missing.yaml": ("region:\n  name: m\n  osm_file: nowhere.osm.pbf\n", "topoloc: nowhere.osm.pbf: OSM file not found (region.osm_file)"),
        "unknown.yaml": ("graph:\n  spacing: 3\n", "topoloc: config: unknown key under 'graph': Additional properties are not allowed ('spacing' was unexpected)"),
        "type.yaml": ("graph:\n  virtual_node_spacing_m: ten\n", "topoloc: config key 'graph.virtual_node_spacing_m': 'ten' is not of type 'number'"),
        "class.yaml": ("graph:\n  highway_classes: [footway]\n", "topoloc: config key 'graph.highway_classes.0': 'footway' is not one of"),
        "two.yaml": ("region:\n  name: t\n  place: Karlsruhe\n", "topoloc: region: set exactly one of region.osm_file, region.place, region.bbox (got ['osm_file', 'place'])"),
    }
    for name, (text, expected) in cases.items():
        proc = workflow.run("-n", "--configfile", workflow.config(name, text), check=False)
        assert proc.returncode == 1, name
        assert [line for line in proc.stderr.splitlines() if line.startswith("topoloc:")][0].startswith(expected), proc.stderr
