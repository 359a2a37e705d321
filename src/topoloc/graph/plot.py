"""The map figure of a road graph: nodes blue, roads green, with edge ids."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from topoloc.geometry import point_along
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path

#: Above this many roads the map is drawn as a city (see :func:`plot_road_graph`).
CITY_EDGES = 3000


def plot_road_graph(graph: RoadGraph, path: str | Path, title: str = "Road graph", label_edges: bool = True) -> None:
    """Draw the graph to ``path`` (PNG), scaled to the map's extent; edge ids at road midpoints.

    A city map (more than :data:`CITY_EDGES` roads) is drawn with thin roads, no node markers and no edge
    ids (13,000 labels or markers would cover the map), at a higher resolution."""
    xy = graph.nodes[["x", "y"]].to_numpy()
    span = np.ptp(xy, axis=0) + 1.0
    city = graph.num_edges > CITY_EDGES
    width = 12.0
    height = float(np.clip(width * span[1] / span[0], 4.0, 16.0))
    fig, ax = plt.subplots(figsize=(width, height), dpi=220 if city else 150)
    ax.add_collection(LineCollection(graph.geometry, colors="tab:green", linewidths=0.3 if city else 1.2, zorder=1))
    if city:
        ax.plot([], [], " ", label=f"{len(xy)} nodes (not drawn)")
    else:
        ax.scatter(xy[:, 0], xy[:, 1], s=8, c="tab:blue", zorder=2, label=f"{len(xy)} nodes")
    if label_edges and not city:
        size = float(np.clip(700.0 / np.sqrt(max(graph.num_edges, 1)), 2.5, 8.0))
        for edge_id, coords in enumerate(graph.geometry):
            length = graph.edges.length_m.iat[edge_id]
            x, y = point_along(coords, length / 2.0)
            ax.text(x, y, str(edge_id), fontsize=size, color="darkgreen", ha="center", va="center", zorder=3)
    ax.plot([], [], color="tab:green", label=f"{graph.num_edges} roads, {graph.edges.length_m.sum() / 1000:.1f} km")
    ax.set_aspect("equal")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.autoscale_view()
    ax.set_xlabel(f"x [m] ({graph.crs})")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
