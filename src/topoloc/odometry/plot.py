"""Figures of the odometry stages: top views on the map, estimate versus ground truth, fitted segments."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from topoloc.graph.road_graph import RoadGraph  # noqa: E402
from topoloc.io import atomic_path  # noqa: E402


def _save(fig, path: str | Path) -> None:
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def _zoom(ax, xy: np.ndarray, margin: float = 60.0) -> None:
    lo, hi = np.nanmin(xy, axis=0) - margin, np.nanmax(xy, axis=0) + margin
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])


def plot_track(graph: RoadGraph, est: np.ndarray, gt: np.ndarray | None, edges: np.ndarray, path: str | Path, title: str) -> None:
    """Top view on the map: roads grey, labelled edges green, ground truth black, odometry blue."""
    fig, ax = plt.subplots(figsize=(9, 9), dpi=120)
    ax.add_collection(LineCollection(graph.geometry, colors="0.8", linewidths=1.0, zorder=1))
    used = sorted(set(int(e) for e in edges))
    ax.add_collection(LineCollection([graph.geometry[e] for e in used], colors="tab:green", linewidths=3.0, alpha=0.6,
                                     zorder=2, label=f"labelled edges ({len(used)})"))
    if gt is not None:
        ax.plot(gt[:, 0], gt[:, 1], "k--", lw=1.0, zorder=3, label="ground truth")
    ax.plot(est[:, 0], est[:, 1], color="tab:blue", lw=1.2, zorder=4, label="odometry")
    ax.plot(*est[0], "o", color="tab:red", zorder=5, label="start")
    _zoom(ax, np.vstack([est] + ([gt] if gt is not None else [])))
    ax.set_aspect("equal")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.set_xlabel(f"x [m] ({graph.crs})")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    _save(fig, path)


def plot_evaluation(gt: np.ndarray | None, est_aligned: np.ndarray | None, path: str | Path, title: str) -> None:
    """Estimate (rigidly aligned) versus ground truth, and the position error along the drive."""
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 6), dpi=110)
    if gt is None or est_aligned is None:
        for a in (ax, ax2):
            a.text(0.5, 0.5, "no ground truth for this drive", ha="center", va="center", transform=a.transAxes)
    else:
        ax.plot(gt[:, 0], gt[:, 1], "k-", lw=1.0, label="ground truth")
        ax.plot(est_aligned[:, 0], est_aligned[:, 1], color="tab:blue", lw=1.0, label="estimate (aligned)")
        ax.set_aspect("equal")
        ax.legend(fontsize=8)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]")
        dist = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(gt, axis=0).T))])
        ax2.plot(dist, np.hypot(*(est_aligned - gt).T), color="tab:red", lw=1.0)
        ax2.set_xlabel("distance driven [m]")
        ax2.set_ylabel("position error after alignment [m]")
        ax2.grid(alpha=0.3)
    fig.suptitle(title)
    _save(fig, path)


def plot_segments(track: np.ndarray, corners: np.ndarray, path: str | Path, title: str) -> None:
    """Like the paper's Fig. 9(a): odometry track in blue, Douglas-Peucker segments in orange."""
    fig, ax = plt.subplots(figsize=(8, 8), dpi=120)
    ax.plot(track[:, 0], track[:, 1], color="tab:blue", lw=2.5, label="odometry")
    ax.plot(track[corners, 0], track[corners, 1], "-o", color="tab:orange", lw=1.2, ms=3,
            label=f"fitted segments ({len(corners) - 1})")
    ax.set_aspect("equal")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(fontsize=8)
    _save(fig, path)
