"""Experiment ``rnn_ablation``: the trajectory RNN's cell, size and inputs, one job per variant (rule ``ablate_rnn``;
the token HMM and the oracle beside them: rule ``ablate_rnn_baseline``), and their summary (``summarize_rnn_ablation``).

A variant is ``CELL-HIDDEN`` (the dataset's continuous features beside the angle token) or ``CELL-HIDDEN-tokens``
(the angle token alone: the paper's input, same paths and labels). Each is trained with the config's ``train`` section
(epochs from the config, so the figures do not depend on the machine's load) and judged by: training wall time;
held-out accuracy over all steps and at 200 / 500 / 1000 m driven (Fig. 8); and, from a start every
``localization.evaluate.start_every_m`` of the region's drives, each localizer's share of starts localized, median
distance to localized and accuracy after.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.experiments.many_starts import evaluate_kitti
from topoloc.experiments.summary import write_summary
from topoloc.io import atomic_path, write_json
from topoloc.trajectory.accuracy import accuracy_by_distance, driven_metres
from topoloc.trajectory.dataset import load_features, load_sequences
from topoloc.trajectory.fitting import fit
from topoloc.trajectory.model import TrajectoryRNN, predict

AT_METRES = (200, 500, 1000)
#: The baseline job's name among the variants.
BASELINE = "hmm"


def parse_variant(name: str) -> tuple[str, int, bool]:
    """``lstm-128`` -> ("lstm", 128, True); ``gru-64-tokens`` -> ("gru", 64, False)."""
    parts = name.split("-")
    if len(parts) not in (2, 3) or not parts[1].isdigit() or (len(parts) == 3 and parts[2] != "tokens"):
        raise InputError("experiments.rnn_ablation.variants", f"{name!r} is not CELL-HIDDEN or CELL-HIDDEN-tokens")
    return parts[0], int(parts[1]), len(parts) == 2


def held_out(model: TrajectoryRNN, val_path: Path, feature_dim: int, spacing_m: float) -> dict[str, float]:
    """Accuracy over every held-out step, and in the 100 m bins that end at 200, 500 and 1000 m driven."""
    tokens, labels = load_sequences(val_path)
    features = load_features(val_path, feature_dim) if feature_dim else None
    model_dim = int(model.hparams.get("feature_dim", 0))
    pred = predict(model, tokens, inputs=features if model_dim else None)
    row = {"heldout_acc": float(np.mean(np.concatenate([p == y for p, y in zip(pred, labels)])))}
    if features is not None:
        table = accuracy_by_distance(pred, labels, driven_metres(features, spacing_m)).set_index("metres")
        for m in AT_METRES:
            row[f"heldout_acc_{m}m"] = float(table.accuracy.get(float(m), np.nan))
    return row


def drive_figures(summary: pd.DataFrame, localizer: str, drives: list[str]) -> dict[str, float]:
    """``<drive>_localized_share``, ``<drive>_median_m``, ``<drive>_accuracy_after`` of one localizer."""
    s = summary.set_index(["drive", "localizer"])
    return {f"{d}_{k}": float(s.loc[(d, localizer), k]) for d in drives
            for k in ("localized_share", "median_m", "accuracy_after")}


def _results(inputs: dict[str, str]) -> Path:
    """The region's results folder (that of its road graph)."""
    return Path(inputs["graph"]).parents[1]


def _write_rows(outputs: dict[str, str], rows: list[dict[str, Any]]) -> dict[str, float]:
    """``rows`` (CSV) and, as metrics, their figures per localizer."""
    with atomic_path(outputs["rows"]) as tmp:
        pd.DataFrame(rows).to_csv(tmp, index=False)
    metrics = {f"{row['localizer']}/{k}": float(v) for row in rows for k, v in row.items()
               if k not in ("variant", "localizer") and np.isfinite(v)}
    write_json(outputs["metrics"], metrics)
    return metrics


def baseline(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """The token HMM and the oracle from many starts of the drives: ``rows`` and ``metrics``."""
    drives = list(conf["rnn_ablation"]["drives"])
    _, summary, _, _ = evaluate_kitti(_results(inputs), conf, ["hmm"], drives=tuple(drives))
    return _write_rows(outputs, [{"variant": name, "localizer": name, **drive_figures(summary, name, drives)}
                                 for name in (BASELINE, "oracle")])


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train the variant ``conf['variant']`` into ``model``, judge it: ``rows`` (one per localizer) and ``metrics``."""
    exp, variant = conf["rnn_ablation"], str(conf["variant"])
    drives = list(exp["drives"])
    stats = json.loads(Path(inputs["stats"]).read_text())
    spacing = json.loads(Path(inputs["graph_stats"]).read_text())["virtual_node_spacing_m"]
    dataset_dim = int(stats.get("feature_dim", 0))
    cell, hidden, with_features = parse_variant(variant)
    if with_features and not dataset_dim:
        raise InputError(inputs["stats"], f"the dataset has no features (dataset.simulated.features) for {variant}")
    vconf = {"encoding": conf["encoding"], "train": conf["train"],
             "model": {**conf["model"], "cell": cell, "hidden_size": hidden}}
    began = time.perf_counter()
    model, _, metrics = fit(vconf, inputs["train"], inputs["val"], int(stats["classes"]), outputs["model"],
                            feature_dim=dataset_dim if with_features else 0)
    row = {"variant": variant, "train_s": time.perf_counter() - began, "epochs": metrics["epochs"],
           "parameters": sum(p.numel() for p in model.parameters()),
           **held_out(model, Path(inputs["val"]), dataset_dim, spacing)}
    _, summary, _, _ = evaluate_kitti(_results(inputs), conf, list(exp["localizers"]), Path(outputs["model"]),
                                      tuple(drives))
    return _write_rows(outputs, [{**row, "localizer": name, **drive_figures(summary, name, drives)}
                                 for name in exp["localizers"]])


def summarize(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """``summary`` (markdown) and ``json``: the rows of the baseline and of every variant (inputs ``rows_<variant>``),
    and per localizer their mean and spread over the variants."""
    exp = conf["rnn_ablation"]
    jobs = pd.concat([pd.read_csv(inputs[f"rows_{v}"]) for v in [BASELINE, *exp["variants"]]], ignore_index=True)
    drives = list(exp["drives"])
    figures = [c for c in ["train_s", "heldout_acc", *(f"heldout_acc_{m}m" for m in AT_METRES),
                           *(f"{d}_{k}" for d in drives for k in ("localized_share", "median_m"))] if c in jobs]
    sentence = (f"The trajectory RNN trained with each of {', '.join(exp['variants'])} (CELL-HIDDEN; -tokens: the angle "
                f"token alone) on the region's dataset, then {', '.join(exp['localizers'])} with it from many starts of "
                f"the drives {', '.join(drives)}, beside the token HMM and the oracle; per localizer the mean and "
                f"sample standard deviation over the variants.")
    write_summary(outputs, "Trajectory RNN ablation", sentence, jobs.sort_values("localizer", kind="stable"), "variant",
                  ["localizer"], figures)
    return {f"{r.localizer}/heldout_acc_max": float(r.heldout_acc)
            for r in jobs.groupby("localizer").max(numeric_only=True).reset_index().itertuples()
            if "heldout_acc" in jobs and np.isfinite(r.heldout_acc)}
