"""Figures of the place-recognition stages: training curves, the topometric map, localization per condition."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from topoloc.io import atomic_path  # noqa: E402
from topoloc.place.topometric_map import COMMANDS  # noqa: E402

COMMAND_COLORS = {"follow": "0.7", "left": "tab:blue", "right": "tab:red", "straight": "tab:green"}
METHOD_COLORS = {"siamese network": "tab:blue", "siamese network + filter": "navy", "raw correlation": "tab:orange",
                 "raw correlation + filter": "saddlebrown", "odometry only": "0.6"}


def _save(fig: Any, path: str | Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def training_figure(history: pd.DataFrame, metrics: dict[str, float], path: str | Path) -> None:
    """Training / validation loss, and validation pair accuracy per condition, against the step."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    if "train/loss" in history:
        rows = history.dropna(subset=["train/loss"])
        ax1.plot(rows.step, rows["train/loss"], lw=0.8, alpha=0.7, label="train (batch)")
    if "val/loss" in history:
        rows = history.dropna(subset=["val/loss"])
        ax1.plot(rows.step, rows["val/loss"], "o-", label="validation (training conditions)")
    ax1.set_xlabel("step")
    ax1.set_ylabel("cross-entropy")
    ax1.legend()
    ax1.set_title("siamese network loss")
    for col in sorted(c for c in history.columns if c.startswith("val/acc_")):
        rows = history.dropna(subset=[col])
        ax2.plot(rows.step, rows[col], "o-", ms=3, label=col.removeprefix("val/acc_"))
    ax2.set_xlabel("step")
    ax2.set_ylabel("pair accuracy (validation routes)")
    ax2.set_ylim(0.4, 1.0)
    ax2.legend(fontsize=8)
    ax2.set_title(f"{metrics.get('steps', 0):.0f} steps in {metrics.get('train_seconds', 0):.0f} s")
    fig.tight_layout()
    _save(fig, path)


def map_figure(topo: Any, crossings: list[Any], path: str | Path) -> None:
    """Vertices at their true and path-integrated positions, coloured by navigation command."""
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot(topo.gt_xy[:, 0], topo.gt_xy[:, 1], "-", color="k", lw=0.8, label="teach drive (ground truth)")
    ax.plot(topo.xy[:, 0], topo.xy[:, 1], "--", color="0.5", lw=0.8, label="vertex positions (path integration)")
    for i, name in enumerate(COMMANDS):
        sel = topo.command == i
        if sel.any():
            ax.scatter(topo.gt_xy[sel, 0], topo.gt_xy[sel, 1], s=6, color=COMMAND_COLORS[name], label=name, zorder=3)
    for c in crossings:
        xy = topo.gt_xy[min(c.frame, len(topo) - 1)]
        ax.annotate(f"{c.command} {c.angle_deg:.0f}", xy, fontsize=7, xytext=(4, 4), textcoords="offset points")
    ax.plot(*topo.gt_xy[0], "ko", ms=6)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=8, loc="best")
    ax.set_title(f"topometric map: {len(topo)} vertices, teach under {topo.condition}")
    fig.tight_layout()
    _save(fig, path)


def bars_figure(summary: pd.DataFrame, path: str | Path, held_out: list[str]) -> None:
    """Share of frames within 5 m (bars) and 2 m (hatched) per condition and method."""
    conditions = list(dict.fromkeys(summary.condition))
    methods = list(dict.fromkeys(summary.method))
    width = 0.8 / len(methods)
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(conditions)), 4))
    x = np.arange(len(conditions))
    for k, method in enumerate(methods):
        rows = summary[summary.method == method].set_index("condition").loc[conditions]
        color = METHOD_COLORS.get(method, None)
        ax.bar(x + k * width, rows.within_5m, width, color=color, label=f"{method} (5 m)")
        ax.bar(x + k * width, rows.within_2m, width, color="none", edgecolor="k", hatch="//", lw=0.5)
    ax.axhline(0.9, color="k", ls=":", lw=0.8)
    ax.set_xticks(x + width * (len(methods) - 1) / 2,
                  [f"{c}\n(held out)" if c in held_out else c for c in conditions])
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("share of repeat frames localized (hatched: within 2 m)")
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title("teach-and-repeat localization per condition")
    fig.tight_layout()
    _save(fig, path)


def errors_figure(frames: pd.DataFrame, path: str | Path) -> None:
    """Localization error along the repeat drive, one panel per condition, with relocalizations marked."""
    conditions = list(dict.fromkeys(frames.condition))
    fig, axes = plt.subplots(len(conditions), 1, figsize=(10, 1.8 * len(conditions) + 0.6), sharex=True, squeeze=False)
    for ax, condition in zip(axes[:, 0], conditions):
        rows = frames[frames.condition == condition]
        for method, group in rows.groupby("method", sort=False):
            ax.plot(group.frame, group.error_m, lw=0.8, color=METHOD_COLORS.get(method), label=method)
            reloc = group[group.event == "reloc_ok"]
            ax.plot(reloc.frame, reloc.error_m, "v", ms=4, color=METHOD_COLORS.get(method))
        ax.axhline(5.0, color="k", ls=":", lw=0.8)
        ax.set_yscale("symlog", linthresh=5.0)
        ax.set_ylabel(f"{condition}\nerror (m)")
    axes[0, 0].legend(fontsize=7, ncol=3, loc="upper left")
    axes[-1, 0].set_xlabel("repeat frame (triangles: global relocalization)")
    fig.tight_layout()
    _save(fig, path)
