"""Stage ``evaluate_rnn``: accuracy at the i-th position (the paper's Eq. 6), Fig. 8a and Fig. 8b.

``Accuracy(i)`` is the fraction of trajectories whose prediction at their
i-th token (virtual nodes included) is the true edge, over the trajectories
that have an i-th token (``n`` in the table); "last" is each trajectory's
last token. Computed for the training and the held-out (validation)
trajectories, next to the ceiling of any causal model (:func:`prefix_majority`).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import pandas as pd

from topoloc.io import atomic_path, write_json, write_text
from topoloc.report_tables import markdown_table
from topoloc.trajectory.accuracy import accuracy_by_distance, accuracy_by_position, driven_metres, prefix_majority
from topoloc.trajectory.dataset import load_features, load_sequences
from topoloc.trajectory.model import load_model, predict
from topoloc.trajectory.plot import plot_accuracy, plot_loss

log = logging.getLogger(__name__)


def accuracy_markdown(tables: dict[str, pd.DataFrame], region: str) -> str:
    """The report of the accuracy per position: its heading and one table, with the columns of every split."""
    merged = None
    for name, table in tables.items():
        part = table.rename(columns={"n": f"n {name}", "accuracy": f"accuracy {name}", "ceiling": f"ceiling {name}"})
        merged = part if merged is None else merged.merge(part, on="position", how="outer", sort=False)
    merged = merged.sort_values("position", key=lambda s: s.map(lambda p: 10**9 if p == "last" else int(p)))
    lines = [f"# Accuracy at the i-th position ({region})", ""]
    if any("ceiling" in table for table in tables.values()):
        lines += ["ceiling: the best any causal model can score (the most frequent edge among all dataset",
                  "trajectories with the same tokens so far).", ""]
    rows = []
    for _, row in merged.iterrows():
        cells = []
        for col in merged.columns:
            value = row[col]
            if col.startswith(("accuracy", "ceiling")):
                cells.append("" if pd.isna(value) else f"{value:.4f}")
            elif col.startswith("n "):
                cells.append("" if pd.isna(value) else str(int(value)))
            else:
                cells.append(f"**{value}**" if value == "last" else str(value))
        rows.append(cells)
    return "\n".join([*lines, markdown_table(list(merged.columns), rows)]) + "\n"


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Evaluate ``inputs['model']`` on ``train``/``val``; write ``table``, ``csv``, ``metrics``, ``loss_figure``, ``accuracy_figure``."""
    region = conf.get("region", "")
    model = load_model(inputs["model"])
    limit = conf["evaluate"]["max_train_trajectories"]
    data = {"train": load_sequences(inputs["train"], limit), "held-out": load_sequences(inputs["val"])}
    dim = int(model.hparams.get("feature_dim", 0))
    features = {"train": load_features(inputs["train"], dim, limit), "held-out": load_features(inputs["val"], dim)} if dim else {}
    predictions = {split: predict(model, tokens, inputs=features.get(split)) for split, (tokens, _) in data.items()}
    tables = {split: accuracy_by_position(predictions[split], labels) for split, (_, labels) in data.items()}
    spacing = json.loads(Path(inputs["graph_stats"]).read_text())["virtual_node_spacing_m"] if "graph_stats" in inputs else None
    distances = {split: accuracy_by_distance(predictions[split], data[split][1], driven_metres(features[split], spacing))
                 for split in data} if dim and spacing else {}
    if conf["evaluate"]["ceiling"]:
        reference = load_sequences(inputs["train"]) if limit is not None else data["train"]
        ref_tokens, ref_labels = reference[0] + data["held-out"][0], reference[1] + data["held-out"][1]
        for split, (tokens, labels) in data.items():
            best = accuracy_by_position(prefix_majority(ref_tokens, ref_labels, tokens), labels)
            tables[split]["ceiling"] = best.accuracy.to_numpy()
    frame = pd.concat([t.assign(split=name) for name, t in tables.items()])
    frame = frame[["split", *(c for c in frame.columns if c != "split")]]
    with atomic_path(outputs["csv"]) as tmp:
        frame.to_csv(tmp, index=False)
    text = accuracy_markdown(tables, region)
    if distances:
        merged = distances["train"].merge(distances["held-out"], on="metres", how="outer", suffixes=(" train", " held-out"))
        text += f"\n# Accuracy against metres driven ({region})\n\n" + merged.to_markdown(index=False, floatfmt=".4f") + "\n"
    write_text(outputs["table"], text)
    history = pd.read_csv(inputs["history"])
    plot_loss(history, outputs["loss_figure"], f"Fig. 8a: loss ({region}, {model.hparams.cell.upper()})")
    plot_accuracy(tables, outputs["accuracy_figure"], f"Fig. 8b: accuracy vs position ({region})", distances=distances)
    metrics: dict[str, float] = {}
    for split, table in tables.items():
        key = split.replace("-", "")
        last = table[table.position == "last"].iloc[0]
        positions = table[table.position != "last"]
        metrics[f"{key}_acc_last"] = float(last.accuracy)
        if "ceiling" in table:
            metrics[f"{key}_ceiling_last"] = float(last.ceiling)
        metrics[f"{key}_trajectories"] = float(last.n)
        for i in (1, 5, 10, 20, 40):
            if i <= len(positions):
                metrics[f"{key}_acc_pos{i}"] = float(positions.accuracy.iloc[i - 1])
    for split, table in distances.items():
        for metres in (200.0, 500.0, 1000.0, 2000.0):
            row = table[table.metres == metres]
            if len(row):
                metrics[f"{split.replace('-', '')}_acc_{metres:.0f}m"] = float(row.accuracy.iloc[0])
    training = json.loads(Path(inputs["train_metrics"]).read_text())
    metrics["train_seconds"] = float(training.get("train_seconds", float("nan")))
    write_json(outputs["metrics"], metrics)
    log.info("evaluation: %s", metrics)
    return metrics
