"""Figures of the trajectory RNN's evaluation: its training curves (Fig. 8a) and its accuracy against the position
in a trajectory and against metres driven (Fig. 8b)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from topoloc.io import atomic_path  # noqa: E402


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
