"""The paper's Fig. 9 for one drive: (a) trajectory, (b) ground truth, (c) initial hypotheses, (d)-(f) decoders, and the baseline."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from topoloc.geometry import point_along  # noqa: E402
from topoloc.graph.road_graph import RoadGraph  # noqa: E402
from topoloc.io import atomic_path  # noqa: E402

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


def plot_fig9(graph: RoadGraph, table: pd.DataFrame, frames: pd.DataFrame, corners: np.ndarray | None,
              initial: list[int], metrics: dict[str, dict[str, float]], path: str | Path, title: str) -> None:
    """Fig. 9 panels for one drive from its decoded table (:func:`topoloc.localization.localize.decoded_table`)."""
    xy = frames[["x", "y"]].to_numpy(float)
    truth = table["true_edge_id"].to_numpy() if "true_edge_id" in table.columns else None
    truth_set = set(int(e) for e in truth) if truth is not None else set()
    extent = _extent(graph, xy, truth_set)  # panels with edges off the route zoom out to show them
    decoders = [name for name in ("raw", "strategy1", "strategy2", "hmm") if f"{name}_path" in table.columns]
    names = {"raw": "(d) raw RNN argmax", "strategy1": "(e) Strategy 1", "strategy2": "(f) Strategy 2", "hmm": "(g) HMM baseline"}
    fig, axes = plt.subplots(2, 4, figsize=(18, 9.5), dpi=100)
    axes = axes.ravel()
    _base(axes[0], graph, extent, "(a) trajectory: odometry (blue), segments (orange)")
    axes[0].plot(xy[:, 0], xy[:, 1], color="tab:blue", lw=2.0, zorder=3)
    if corners is not None and len(corners):
        axes[0].plot(xy[corners, 0], xy[corners, 1], "-o", color="tab:orange", lw=1.0, ms=2.5, zorder=4)
    axes[0].plot(*xy[0], "k^", ms=6, zorder=5)
    _base(axes[1], graph, extent, "(b) ground-truth edges")
    if truth is not None:
        _edges(axes[1], graph, sorted(truth_set), "tab:green")
    _base(axes[2], graph, _extent(graph, xy, truth_set | set(initial)), f"(c) top {len(initial)} initial hypotheses")
    _edges(axes[2], graph, initial, [plt.cm.viridis(i / max(1, len(initial))) for i in range(len(initial))], labels=True)
    for ax, name in zip(axes[3:7], decoders):
        m = metrics.get(name, {})
        col = "raw_online" if name == "raw" else f"{name}_path"
        sub = f"acc {m.get('path_accuracy', np.nan):.2f}, consistent {m.get('consistency', np.nan):.2f}"
        if name != "raw":
            loc = m.get("localized_m", np.nan)
            sub += f"\nonline acc {m.get('accuracy', np.nan):.2f}, localized " + (f"after {loc:.0f} m" if np.isfinite(loc) else "never")
        _base(ax, graph, _extent(graph, xy, truth_set | set(table[col].tolist())), f"{names[name]}: {sub}")
        _decoded(ax, graph, table[col].to_numpy(), truth_set)
    for ax in axes[3 + len(decoders):]:
        ax.axis("off")
    fig.suptitle(title + "   (decoded edges: blue on the true route, red off it; triangle: start)", fontsize=11)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
