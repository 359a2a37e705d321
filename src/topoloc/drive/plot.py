"""Figures of the drive stages: demonstration sheets, training curves, driven paths, success rates, frame strips."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.place.topometric_map import COMMANDS

OUTCOME_COLORS = {"success": "tab:green", "off_road": "tab:red", "wrong_road": "tab:orange", "reversed": "tab:purple",
                  "timeout": "0.5"}


def _save(fig: Any, path: str | Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def _rgb(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB) if image.shape[-1] == 3 else np.repeat(image, 3, axis=-1)


def frame_grid(rows: list[tuple[str, list[tuple[NDArray[np.uint8], str]]]], path: str | Path, title: str) -> None:
    """A grid of camera images: one row per (label, [(image, caption), ...])."""
    cols = max(len(r[1]) for r in rows)
    h, w = rows[0][1][0][0].shape[:2]
    fig, axes = plt.subplots(len(rows), cols, figsize=(cols * 2.2 * w / max(w, 1) * 1.0, len(rows) * 2.2 * h / w + 0.6),
                             squeeze=False)
    for r, (label, items) in enumerate(rows):
        for c in range(cols):
            ax = axes[r, c]
            ax.axis("off")
            if c < len(items):
                ax.imshow(_rgb(items[c][0]))
                ax.set_title(items[c][1], fontsize=6)
        axes[r, 0].text(-0.05, 0.5, label, transform=axes[r, 0].transAxes, ha="right", va="center", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def demonstrations_sheet(demos: Any, path: str | Path, per_condition: int = 6) -> None:
    """Sample steps of each condition: image with command, steering label and whether perturbed."""
    rows = []
    for c, name in enumerate(demos.conditions):
        idx = np.flatnonzero(demos.condition == c)
        turns = idx[demos.command[idx] != 0]
        pick = np.unique(np.concatenate([idx[np.linspace(0, len(idx) - 1, per_condition // 2).astype(int)] if len(idx) else [],
                                         turns[np.linspace(0, len(turns) - 1, per_condition - per_condition // 2).astype(int)]
                                         if len(turns) else []]).astype(int))
        rows.append((name, [(demos.images[k], (f"{COMMANDS[demos.command[k]]} steer {demos.steer[k]:+.2f}"
                             f"{' noise' if demos.perturbed[k] else ''}")) for k in pick[:per_condition]]))
    frame_grid([r for r in rows if r[1]], path, f"expert demonstrations: {len(demos)} steps")


def training_figure(history: pd.DataFrame, path: str | Path, name: str = "Topo-DLM",
                    metrics: dict[str, float] | None = None) -> None:
    """Training and validation loss of controller ``name`` against the step (DAgger rounds marked; the closed-loop
    check's success rate in the title when ``metrics`` hold it)."""
    fig, ax = plt.subplots(figsize=(7, 4))
    if "train/loss" in history:
        rows = history.dropna(subset=["train/loss"])
        ax.plot(rows.step, rows["train/loss"], lw=0.8, alpha=0.7, label="train (batch)")
    for key, style in (("val/loss", "o-"), ("val/steer_mae", "s--")):
        if key in history:
            rows = history.dropna(subset=[key])
            ax.plot(rows.step, rows[key], style, label=key)
    if "round" in history:  # DAgger: each round trains on from the last
        for k, rows in history.groupby("round"):
            if k > 0 and len(rows):
                ax.axvline(float(rows.step.min()), color="0.6", lw=0.8, ls=":")
                ax.text(float(rows.step.min()), 1.0, f" DAgger {int(k)}", transform=ax.get_xaxis_transform(), va="top",
                        fontsize=8, color="0.4")
    ax.set_xlabel("step")
    ax.set_yscale("log")
    ax.legend()
    branch = " of the commanded branch" if name == "Topo-DLM" else ""  # Topo-LP has one head
    title = f"{name} training (weighted MSE{branch})"
    if metrics and "check/success_rate" in metrics:
        title += (f"\nclosed-loop check: {metrics['check/success_rate']:.2f} of {int(metrics['check/routes'])} unseen routes "
                  f"finished, {metrics['check/share_driven']:.2f} of their length driven")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def paths_figure(graph: RoadGraph, lanes: list[NDArray[np.float64]], episodes: pd.DataFrame,
                 traces: dict[str, NDArray[np.float64]], path: str | Path) -> None:
    """The driven paths of every episode over the road map and the routes' lanes (start: a dot), one panel per agent
    (three to a row), coloured by outcome."""
    agents = list(dict.fromkeys(episodes.agent))
    cols = min(3, len(agents))
    rows = -(-len(agents) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.5 * cols, 5.5 * rows), squeeze=False)
    every = np.vstack(lanes)
    lo, hi = every.min(axis=0) - 40, every.max(axis=0) + 40
    roads = [c for c in graph.geometry if np.any(np.all((c >= lo) & (c <= hi), axis=1))]
    for ax in axes.flat[len(agents):]:
        ax.axis("off")
    for ax, agent in zip(axes.flat, agents):
        for coords in roads:
            ax.plot(coords[:, 0], coords[:, 1], color="0.85", lw=3, zorder=1)
        for k, lane in enumerate(lanes):
            ax.plot(lane[:, 0], lane[:, 1], "k--", lw=0.8, label="route (lane)" if k == 0 else None, zorder=2)
            ax.plot(*lane[0], "ko", ms=5)
        for row in episodes[episodes.agent == agent].itertuples():
            xy = traces[row.episode]
            ax.plot(xy[:, 0], xy[:, 1], color=OUTCOME_COLORS.get(row.outcome, "k"), lw=0.9, alpha=0.8, zorder=3)
            if row.outcome != "success":
                ax.plot(*xy[-1], "x", color=OUTCOME_COLORS.get(row.outcome, "k"), ms=6, zorder=4)
        for outcome, color in OUTCOME_COLORS.items():
            ax.plot([], [], color=color, label=outcome)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        rate = float((episodes[episodes.agent == agent].outcome == "success").mean())
        ax.set_title(f"{agent}: success {rate:.2f}", fontsize=9)
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    _save(fig, path)


def success_figure(summary: pd.DataFrame, path: str | Path, held_out: list[str]) -> None:
    """Success rate per condition (bars) for every agent."""
    conditions = list(dict.fromkeys(summary.condition))
    agents = list(dict.fromkeys(summary.agent))
    width = 0.8 / len(agents)
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(conditions)), 4))
    x = np.arange(len(conditions))
    for k, agent in enumerate(agents):
        rows = summary[summary.agent == agent].set_index("condition").loc[conditions]
        ax.bar(x + (k - (len(agents) - 1) / 2) * width, rows.success_rate, width, label=agent)
    ax.set_xticks(x, [f"{c}\n(held out)" if c in held_out else c for c in conditions])
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("success rate")
    ax.legend(fontsize=7)
    ax.set_title("closed-loop route following per condition")
    fig.tight_layout()
    _save(fig, path)


def junction_figure(rates: dict[str, pd.DataFrame], path: str | Path) -> None:
    """Share of junctions taken as commanded per agent: one panel per grouping (``rates``: title -> the
    ``rate`` / ``reached`` frame of :func:`topoloc.drive.junctions.junction_rates`), the junctions reached on each bar."""
    fig, axes = plt.subplots(1, max(1, len(rates)), figsize=(6.5 * max(1, len(rates)), 4.2), squeeze=False)
    if not rates:
        axes[0][0].text(0.5, 0.5, "the routes pass no junction", ha="center", va="center")
        axes[0][0].set_axis_off()
    for ax, (title, table) in zip(axes[0], rates.items()):
        rate, reached = table["rate"], table["reached"]
        groups, agents = list(rate.columns), list(rate.index)
        width = 0.8 / max(len(agents), 1)
        x = np.arange(len(groups))
        for k, agent in enumerate(agents):
            bars = ax.bar(x + (k - (len(agents) - 1) / 2) * width, rate.loc[agent].fillna(0.0), width, label=agent)
            for bar, n in zip(bars, reached.loc[agent]):
                if n == n:  # not NaN: some reached
                    ax.text(bar.get_x() + bar.get_width() / 2, bar.get_height() + 0.01, f"{int(n)}", ha="center",
                            fontsize=5)
        ax.set_xticks(x, groups, fontsize=8)
        ax.set_ylim(0, 1.1)
        ax.set_ylabel("share taken as commanded")
        ax.set_title(f"junctions by {title} (number reached on the bars)")
    if rates:
        axes[0][0].legend(fontsize=6)
    fig.tight_layout()
    _save(fig, path)
