"""Hand-made graphs and logits for the localization and CLI tests."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "trajectory"))

from trajectory_helpers import make_graph


def corridor_graph():
    """A corridor 0-1-2-3 (edges 0, 1, 2; 100 m each) and, far away, 4-5-6 (edges 3, 4); edge 1 one-way 1 -> 2."""
    coords = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (200.0, 0.0), 3: (300.0, 0.0),
              4: (0.0, 500.0), 5: (100.0, 500.0), 6: (200.0, 500.0)}
    return make_graph(coords, [(0, 1), (1, 2, 1), (2, 3), (4, 5), (5, 6)])


def peaked_logits(sequence, num_edges, overrides=None, peak=4.0):
    """Logits peaked on ``sequence[t]``; ``overrides`` {t: {edge: logit}} change single entries."""
    logits = np.zeros((len(sequence), num_edges))
    logits[np.arange(len(sequence)), sequence] = peak
    for t, entries in (overrides or {}).items():
        for edge, value in entries.items():
            logits[t, edge] = value
    return logits


def irregular_grid():
    """A 5 x 4 grid with irregular block lengths (so distances tell places apart), two-way roads."""
    xs, ys = [0, 90, 210, 280, 400], [0, 130, 200, 340]
    coords = {j * len(xs) + i: (float(x), float(y)) for j, y in enumerate(ys) for i, x in enumerate(xs)}
    edges = [(j * len(xs) + i, j * len(xs) + i + 1) for j in range(len(ys)) for i in range(len(xs) - 1)]
    edges += [(j * len(xs) + i, (j + 1) * len(xs) + i) for j in range(len(ys) - 1) for i in range(len(xs))]
    return make_graph(coords, edges), edges


def mirror_loop(length: float = 400.0, gap: float = 17.0):
    """A dual carriageway: two one-way roads ``gap`` metres apart, east 0 -> 1 at y = 0 (edge 0) and west 2 -> 3 at
    y = ``gap`` (edge 3), joined by a U-turn at each end (east: 1 -> 4 -> 2, edges 1, 2; west: 3 -> 5 -> 0, edges 4,
    5). The map is point-symmetric (a half turn about its centre maps it onto itself), so every walk has a mirror
    walk on the other carriageway that odometry alone cannot tell from it."""
    half = gap / 2.0
    coords = {0: (0.0, 0.0), 1: (length, 0.0), 2: (length, gap), 3: (0.0, gap), 4: (length + half, half), 5: (-half, half)}
    return make_graph(coords, [(0, 1, 1), (1, 4, 1), (4, 2, 1), (2, 3, 1), (3, 5, 1), (5, 0, 1)])


def drive_along(graph, route, edges, start_m: float = 0.0, every_m: float = 1.0):
    """Points every ``every_m`` along the nodes of ``route`` (from ``start_m`` on), their heading of travel and the
    true edge of each (``edges[(a, b)]``)."""
    xy, labels = [], []
    for a, b in zip(route[:-1], route[1:]):
        p, q = graph.nodes.loc[a, ["x", "y"]].to_numpy(float), graph.nodes.loc[b, ["x", "y"]].to_numpy(float)
        n = max(1, int(round(np.hypot(*(q - p)) / every_m)))
        xy.append(p + (q - p) * np.arange(n)[:, None] / n)
        labels += [edges[(a, b)]] * n
    xy, labels = np.vstack(xy), np.asarray(labels, np.int64)
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    keep = driven >= start_m
    step = np.diff(xy, axis=0, append=xy[-1:] + (xy[-1:] - xy[-2:-1]))
    return xy[keep], np.arctan2(step[:, 1], step[:, 0])[keep], labels[keep]
