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

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from topoloc.io import atomic_path, write_json, write_text  # noqa: E402
from topoloc.report_tables import markdown_table  # noqa: E402
from topoloc.trajectory.accuracy import (  # noqa: E402
    accuracy_by_distance,
    accuracy_by_position,
    driven_metres,
    prefix_majority,
)
from topoloc.trajectory.dataset import load_features, load_sequences  # noqa: E402
from topoloc.trajectory.model import load_model, predict  # noqa: E402

log = logging.getLogger(__name__)


def plot_loss(history: pd.DataFrame, path: str, title: str) -> None:
    """Fig. 8a: training loss (per logged step) and validation loss (per epoch) against epochs."""
    fig, ax = plt.subplots(figsize=(6, 4))
    steps_per_epoch = max(1.0, history.step.max() / max(1.0, history.epoch.max() + 1)) if len(history) else 1.0
    train = history.dropna(subset=["train/loss"])
    val = history.dropna(subset=["val/loss"])
    ax.plot(train.step / steps_per_epoch, train["train/loss"], lw=0.8, alpha=0.7, label="training loss (batch)")
    if len(train) > 10:
        ax.plot(train.step / steps_per_epoch, train["train/loss"].rolling(max(3, len(train) // 30), min_periods=1).mean(), lw=1.5, label="training loss (smoothed)")
    ax.plot(val.step / steps_per_epoch, val["val/loss"], "o-", label="validation loss")
    ax.set_xlabel("epoch")
    ax.set_ylabel("cross-entropy (NLL)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


def plot_accuracy(tables: dict[str, pd.DataFrame], path: str, title: str, min_fraction: float = 0.01,
                  distances: dict[str, pd.DataFrame] | None = None) -> None:
    """Fig. 8b: accuracy against position; positions held by fewer than ``min_fraction`` of trajectories are cut.

    With ``distances`` (:func:`accuracy_by_distance` per split) a second panel shows accuracy against metres driven.
    """
    if distances:
        fig, (ax, right) = plt.subplots(1, 2, figsize=(13, 4))
        for name, table in distances.items():
            keep = table[table.n >= min_fraction * table.n.max()]
            right.plot(keep.metres, keep.accuracy, ".-", label=name)
        right.set_xlabel("metres driven (bins of 100 m, upper edge)")
        right.set_ylabel("accuracy over the tokens in the bin")
        right.set_ylim(0, 1.02)
        right.grid(alpha=0.3)
        right.legend(loc="lower right")
    else:
        fig, ax = plt.subplots(figsize=(8, 4))
    shown = {}
    for name, table in tables.items():
        positions = table[table.position != "last"]
        total = table.loc[table.position == "last", "n"].iloc[0]
        shown[name] = (positions[positions.n >= min_fraction * total], total, table.loc[table.position == "last", "accuracy"].iloc[0])
    cut = max(len(keep) for keep, _, _ in shown.values())
    for name, (keep, total, last) in shown.items():
        line = ax.plot(np.arange(1, len(keep) + 1), keep.accuracy, ".-", label=f"{name} (N={total})")
        ax.plot([cut + 2], [last], "s", color=line[0].get_color())
        if "ceiling" in keep:
            ceiling = tables[name].loc[tables[name].position == "last", "ceiling"].iloc[0]
            ax.plot(np.arange(1, len(keep) + 1), keep.ceiling, "--", lw=0.9, color=line[0].get_color(),
                    label=f"{name}: best causal guess")
            ax.plot([cut + 2], [ceiling], "_", ms=14, color=line[0].get_color())
    ticks = list(range(0, cut + 1, max(1, cut // 10)))
    ax.set_xticks([*ticks, cut + 2], [*map(str, ticks), "last"])
    ax.set_xlabel("i-th position in trajectory (virtual nodes included)")
    ax.set_ylabel("accuracy (Eq. 6)")
    ax.set_ylim(0, 1.02)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


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
