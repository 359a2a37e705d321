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
