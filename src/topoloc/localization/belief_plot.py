"""The belief of the metric filter over a whole map at a few moments of a drive: where could I be now?

Each panel draws every road of the map in light grey and every road that holds probability in colour
(log scale, from a millionth of the most probable road up), the true position as a star and the drive so
far as a thin line, and an inset around the truth; the title says how far the vehicle has driven, over
how many roads and how many kilometres of road 99 % of the mass is spread, and the probability within
:data:`NEAR_M` of the true position.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import LogNorm
from numpy.typing import NDArray

from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path


@dataclass(frozen=True)
class BeliefSnapshot:
    """One moment: metres driven, probability per road (undirected edge), true road and position, the track so far,
    and the probability within :data:`NEAR_M` of the true position."""

    driven_m: float
    road_prob: NDArray[np.float64]
    true_edge: int
    true_xy: NDArray[np.float64]
    track_xy: NDArray[np.float64]
    near_true: float


#: Radius around the true position whose probability each panel names, metres; half-width of the zoomed inset.
NEAR_M, ZOOM_M = 10.0, 400.0


def near_mass(cell_xy: NDArray[np.float64], weight: NDArray[np.float64], true_xy: NDArray[np.float64]) -> float:
    """Probability of the positions within :data:`NEAR_M` of ``true_xy``."""
    return float(weight[np.hypot(*(cell_xy - true_xy).T) <= NEAR_M].sum())


def spread(road_prob: NDArray[np.float64], length_m: NDArray[np.float64], mass: float = 0.99) -> tuple[int, float]:
    """Fewest roads (most probable first) that hold ``mass`` of the probability, and their length in km."""
    order = np.argsort(-road_prob)
    total = road_prob.sum()
    if total <= 0:
        return 0, 0.0
    k = int(np.searchsorted(np.cumsum(road_prob[order]), mass * total) + 1)
    k = min(k, len(order))
    return k, float(length_m[order[:k]].sum() / 1000.0)


def _draw(ax, graph: RoadGraph, snap: BeliefSnapshot, width: float):
    """Roads grey, roads with probability coloured, the track and the truth; the coloured collection (or None)."""
    ax.add_collection(LineCollection(graph.geometry, colors="0.85", linewidths=0.3 * width, zorder=1))
    top = float(snap.road_prob.max()) if len(snap.road_prob) else 0.0
    held = np.flatnonzero(snap.road_prob >= 1e-6 * top) if top > 0 else np.zeros(0, np.int64)
    held = held[np.argsort(snap.road_prob[held])]  # the most probable drawn last, on top
    lines = None
    if len(held):
        lines = LineCollection([graph.geometry[e] for e in held], array=snap.road_prob[held] / top, cmap="inferno_r",
                               norm=LogNorm(vmin=1e-6, vmax=1.0), linewidths=width, zorder=2)
        ax.add_collection(lines)
    ax.plot(*snap.track_xy.T, color="tab:blue", lw=0.5 * width, alpha=0.7, zorder=3)
    ax.plot(*snap.true_xy, marker="*", color="tab:green", ms=5 * width, mec="black", mew=0.5, zorder=4)
    return lines


def plot_belief(graph: RoadGraph, snapshots: list[BeliefSnapshot], path: str | Path, title: str) -> None:
    """Panels of the belief over the whole map (see the module docstring), written atomically to ``path``."""
    if not snapshots:
        raise ValueError("plot_belief: no snapshots")
    length = graph.edges.length_m.to_numpy(float)
    allxy = np.vstack(graph.geometry)
    lo, hi = allxy.min(axis=0), allxy.max(axis=0)
    cols = min(len(snapshots), 3)
    rows = int(np.ceil(len(snapshots) / cols))
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1.0)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols + 1.2, (6.0 * aspect + 0.8) * rows + 0.6), squeeze=False)
    for ax in axes.ravel()[len(snapshots):]:
        ax.axis("off")
    mappable = None
    for ax, snap in zip(axes.ravel(), snapshots):
        zoom = ax.inset_axes([0.64, 0.56, 0.36, 0.44])  # a close-up around the truth: from everywhere to one road
        for panel, width in ((ax, 1.4), (zoom, 2.5)):
            mappable = _draw(panel, graph, snap, width) or mappable
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        zoom.set_xlim(snap.true_xy[0] - ZOOM_M, snap.true_xy[0] + ZOOM_M)
        zoom.set_ylim(snap.true_xy[1] - ZOOM_M, snap.true_xy[1] + ZOOM_M)
        for panel in (ax, zoom):
            panel.set_aspect("equal")
            panel.set_xticks([])
            panel.set_yticks([])
        ax.indicate_inset_zoom(zoom, edgecolor="0.4")
        roads, km = spread(snap.road_prob, length)
        ax.set_title(f"after {snap.driven_m:.0f} m: 99 % on {roads} roads ({km:.1f} km); "
                     f"P(within {NEAR_M:.0f} m of the truth) = {snap.near_true:.2g}", fontsize=9)
    if mappable is not None:
        fig.colorbar(mappable, ax=axes.ravel().tolist(), fraction=0.015, pad=0.01,
                     label="probability of the road / that of the most probable")
    fig.suptitle(title, fontsize=11)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, format=Path(path).suffix.lstrip(".") or "png")
    plt.close(fig)
