"""The cluster profiles: every rule of the workflow has measured threads / memory / run time; GPUs for training."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]


def _measure_resources():
    spec = importlib.util.spec_from_file_location("measure_resources", REPO / "cluster" / "measure_resources.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_rule_has_measured_resources_in_both_profiles():
    rules = set(_measure_resources().workflow_rules()) - {"all"}
    assert {"build_graph", "train_rnn", "train_retrieval", "summarize_regions"} <= rules
    assert not rules & {"localize_simulated", "ablate_rnn", "experiment_city"}  # experiments: default resources
    for name in ("slurm", "slurm-gpu"):
        profile = yaml.safe_load((REPO / "profiles" / name / "config.yaml").read_text())
        assert profile["executor"] == "slurm"
        resources = profile["set-resources"]
        assert set(resources) == rules, f"profiles/{name}: rerun cluster/measure_resources.py --write"
        assert all(res["mem_mb"] >= 512 and res["runtime"] >= 10 for res in resources.values())
        gpus = {rule for rule, res in resources.items() if res.get("gpu")}
        assert gpus == ({"train_rnn", "train_retrieval", "train_controller"} if name == "slurm-gpu" else set())
        # train_rnn's own threads follow --cores: a scheduler needs a number
        assert profile["set-threads"]["train_rnn"] >= 1


def test_resources_from_benchmark_rows():
    measure = _measure_resources()
    rows = [{"s": 50.0, "max_rss": 900.0, "mean_load": 120.0}, {"s": 300.0, "max_rss": 400.0, "mean_load": 80.0}]
    assert measure.resources(rows, None) == (2, {"mem_mb": 1536, "runtime": 15})
    assert measure.resources(rows, 60) == (2, {"mem_mb": 1536, "runtime": 70})  # the safety cap, not Slurm, ends training
    assert measure.resources([{"s": 1.0, "max_rss": 10.0, "mean_load": 5.0}], None) == (1, {"mem_mb": 512, "runtime": 10})
