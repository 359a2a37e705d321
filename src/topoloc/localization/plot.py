"""Figures of the localization evaluation: the paper's Fig. 9 for one drive (trajectory, ground truth, initial
hypotheses, every localizer's path) and the distribution of the distance to localized over many starts."""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.collections import LineCollection

from topoloc.geometry import point_along
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.localization.evaluation import quantile

RIGHT, WRONG = "tab:blue", "tab:red"


def _extent(graph: RoadGraph, xy: np.ndarray, edges) -> np.ndarray:
    """Bounding box of the track and ``edges``, padded."""
    allxy = np.vstack([xy] + [graph.geometry[int(e)] for e in set(edges)])
    lo, hi = allxy.min(axis=0), allxy.max(axis=0)
    pad = 0.06 * float(max(hi - lo)) + 30.0
    return np.array([lo - pad, hi + pad])


def _base(ax, graph: RoadGraph, extent: np.ndarray, title: str) -> None:
    ax.add_collection(LineCollection(graph.geometry, colors="0.82", linewidths=0.8, zorder=1))
    (x0, y0), (x1, y1) = extent
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=9)


def _edges(ax, graph: RoadGraph, edges, colors, width: float = 3.0, labels: bool = False) -> None:
    edges = list(edges)
    if not edges:
        return
    ax.add_collection(LineCollection([graph.geometry[e] for e in edges], colors=colors, linewidths=width, alpha=0.85, zorder=2))
    if labels:
        for e in edges:
            x, y = point_along(graph.geometry[e], graph.edges.length_m.iat[e] / 2.0)
            ax.text(x, y, str(e), fontsize=6, ha="center", va="center", zorder=3, clip_on=True,
                    bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7})


def _decoded(ax, graph: RoadGraph, sequence: np.ndarray, truth_set: set[int], distance: np.ndarray | None = None) -> None:
    """Edges of a decoded sequence: right (in the ground-truth route) blue, wrong red; the start marked."""
    used = list(dict.fromkeys(int(e) for e in sequence))
    _edges(ax, graph, used, [RIGHT if e in truth_set else WRONG for e in used])
    start = graph.geometry[int(sequence[0])]
    ax.plot(*point_along(start, graph.edges.length_m.iat[int(sequence[0])] / 2.0), "k^", ms=5, zorder=4)


def plot_fig9(graph: RoadGraph, answers: pd.DataFrame, frames: pd.DataFrame, corners: np.ndarray | None,
              initial: list[int], metrics: dict[str, dict[str, float]], labels: dict[str, str], path: str | Path,
              title: str) -> None:
    """Fig. 9 panels for one drive from frame 0: (a) trajectory, (b) truth, (c) initial hypotheses, then the
    traced-back path of every localizer in ``answers`` (the rows of the frame-0 run; raw: its online answers)."""
    xy = frames[["x", "y"]].to_numpy(float)
    truth_set = set(int(e) for e in frames["edge_id"])
    extent = _extent(graph, xy, truth_set)  # panels with edges off the route zoom out to show them
    names = list(dict.fromkeys(answers.localizer))[:5]
    fig, axes = plt.subplots(2, 4, figsize=(18, 9.5), dpi=100)
    axes = axes.ravel()
    _base(axes[0], graph, extent, "(a) trajectory: odometry (blue), segments (orange)")
    axes[0].plot(xy[:, 0], xy[:, 1], color="tab:blue", lw=2.0, zorder=3)
    if corners is not None and len(corners):
        axes[0].plot(xy[corners, 0], xy[corners, 1], "-o", color="tab:orange", lw=1.0, ms=2.5, zorder=4)
    axes[0].plot(*xy[0], "k^", ms=6, zorder=5)
    _base(axes[1], graph, extent, "(b) ground-truth edges")
    _edges(axes[1], graph, sorted(truth_set), "tab:green")
    _base(axes[2], graph, _extent(graph, xy, truth_set | set(initial)), f"(c) top {len(initial)} initial hypotheses")
    _edges(axes[2], graph, initial, [plt.cm.viridis(i / max(1, len(initial))) for i in range(len(initial))], labels=True)
    for index, (ax, name) in enumerate(zip(axes[3:], names)):
        run = answers[answers.localizer == name]
        sequence = (run.state if name == "raw" else run.path).to_numpy()
        sequence = sequence[sequence >= 0]
        m = metrics.get(name, {})
        loc = m.get("localized_m", np.nan)
        sub = (f"path acc {m.get('path_accuracy', np.nan):.2f}, consistent {m.get('consistency', np.nan):.2f}\n"
               f"online acc {m.get('accuracy', np.nan):.2f}, localized " + (f"after {loc:.0f} m" if np.isfinite(loc) else "never"))
        _base(ax, graph, _extent(graph, xy, truth_set | set(sequence.tolist())), f"({chr(ord('d') + index)}) {labels.get(name, name)}: {sub}")
        if len(sequence):
            _decoded(ax, graph, sequence, truth_set)
    for ax in axes[3 + len(names):]:
        ax.axis("off")
    fig.suptitle(title + "   (edges: blue on the true route, red off it; triangle: start)", fontsize=11)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def plot_cdf(starts: pd.DataFrame, labels: dict[str, str], path: str | Path, title: str) -> None:
    """Share of the starts localized within each distance driven, per localizer, the oracle dashed."""
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=110)
    top = np.nanmax(np.where(np.isfinite(starts.localized_m), starts.localized_m, np.nan)) if starts.localized_m.notna().any() else 1000.0
    grid = np.linspace(0.0, max(100.0, 1.05 * top), 400)
    for name, group in starts.groupby("localizer", sort=False):
        values = group.localized_m.to_numpy(float)
        share = (values[None, :] <= grid[:, None]).mean(axis=1)  # NaN (never) never counts
        oracle = name == "oracle"
        ax.plot(grid, share, ls="--" if oracle else "-", color="k" if oracle else None, lw=2.2 if oracle else 1.6,
                label=f"{labels.get(name, name)} (median {quantile(values, 50):.0f} m)"
                if np.isfinite(values).mean() >= 0.5 else f"{labels.get(name, name)} (localized {np.isfinite(values).mean():.0%})")
    ax.set_xlabel("distance driven from the start (m)")
    ax.set_ylabel("share of starts localized")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def plot_reliability(diagrams: dict[str, pd.DataFrame], path: str | Path, title: str) -> None:
    """Reliability diagrams (:func:`topoloc.localization.calibration.reliability`), one line per localizer: the share
    of right answers per confidence bin against the bin's mean confidence (the diagonal is perfect calibration),
    with the number of answers per bin below."""
    fig, (ax, counts) = plt.subplots(2, 1, figsize=(6.0, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="perfectly calibrated")
    width = 0.8 / max(1, len(diagrams)) / len(next(iter(diagrams.values()), [0]))
    for k, (name, table) in enumerate(diagrams.items()):
        filled = table[table.answers > 0]
        line, = ax.plot(filled.confidence, filled.share_right, "o-", ms=4, label=name)
        centre = (table.low + table.high).to_numpy() / 2 + (k - (len(diagrams) - 1) / 2) * width
        counts.bar(centre, table.answers, width, color=line.get_color())
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_ylabel("share of answers right")
    ax.set_title(textwrap.fill(title, 80), fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    counts.set_yscale("symlog")
    counts.set_xlabel("confidence of the answer")
    counts.set_ylabel("answers")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)
