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


def dual_carriageway(length: float = 900.0, gap: float = 17.0, south_sides: tuple[float, ...] = (),
                     north_sides: tuple[float, ...] = (), round_ends: bool = False):
    """A dual carriageway: an eastbound one-way road at y = 0 and a westbound one at y = ``gap``, joined at each end
    by a one-way U-turn (straight across, or with ``round_ends`` via a node ``gap / 2`` beyond the end), and two-way
    side roads (150 m) off the south and north carriageways at ``south_sides`` and ``north_sides`` (x). Without side
    roads the map is point-symmetric (a half turn about its centre maps it onto itself), so every walk has a mirror
    walk on the other carriageway that odometry alone cannot tell from it; side roads at unmirrored places keep it
    so for a vehicle that drives straight past them.

    Nodes: the south carriageway's by x, the north one's from east to west, the U-turn nodes (east, west), the side
    roads' ends; edges in driving order round the loop (south, east U-turn, north, west U-turn), then the side
    roads. Without side roads and with ``round_ends``: edges 0 (0 -> 1, east), 1, 2 (1 -> 4 -> 2), 3 (2 -> 3, west),
    4, 5 (3 -> 5 -> 0). Returns the graph and the node ids by x of the south and the north carriageway."""
    coords: dict[int, tuple[float, float]] = {}

    def node(x: float, y: float) -> int:
        coords[len(coords)] = (float(x), float(y))
        return len(coords) - 1

    sx, nx = sorted({0.0, length, *south_sides}), sorted({0.0, length, *north_sides})
    south = {x: node(x, 0.0) for x in sx}
    north = {x: node(x, gap) for x in reversed(nx)}
    half = gap / 2.0
    east_end, west_end = (node(length + half, half), node(-half, half)) if round_ends else (None, None)

    def u_turn(a: int, via: int | None, b: int) -> list[tuple[int, int, int]]:
        return [(a, b, 1)] if via is None else [(a, via, 1), (via, b, 1)]

    edges = [(south[a], south[b], 1) for a, b in zip(sx[:-1], sx[1:])]
    edges += u_turn(south[length], east_end, north[length])
    edges += [(north[b], north[a], 1) for a, b in zip(nx[:-1], nx[1:])][::-1]
    edges += u_turn(north[0.0], west_end, south[0.0])
    edges += [(south[x], node(x, -150.0)) for x in south_sides] + [(north[x], node(x, gap + 150.0)) for x in north_sides]
    return make_graph(coords, edges), south, north


def loop_nodes(south: dict[float, int], north: dict[float, int], laps: int) -> list[int]:
    """Node sequence of ``laps`` laps east on the south carriageway and back west on the north one (straight-across
    U-turns)."""
    lap = [south[x] for x in sorted(south)] + [north[x] for x in sorted(north, reverse=True)]
    return lap * laps + [lap[0]]


def drive_along(graph, route: list[int], start_m: float = 0.0, every_m: float = 1.0):
    """Frames every ``every_m`` metres along the roads between the nodes of ``route``, from ``start_m`` on: their
    positions, heading of travel, true edge (the road between the two nodes, either way) and metres driven from the
    first frame."""
    xy, labels = [], []
    u, v = graph.edges.u.to_numpy(), graph.edges.v.to_numpy()
    for a, b in zip(route[:-1], route[1:]):
        edge = int(np.flatnonzero(((u == a) & (v == b)) | ((u == b) & (v == a)))[0])
        p, q = graph.nodes.loc[a, ["x", "y"]].to_numpy(float), graph.nodes.loc[b, ["x", "y"]].to_numpy(float)
        n = max(1, int(round(np.hypot(*(q - p)) / every_m)))
        xy.append(p + (q - p) * np.arange(n)[:, None] / n)
        labels += [edge] * n
    xy, labels = np.vstack(xy), np.asarray(labels, np.int64)
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    keep = driven >= start_m - 1e-9
    step = np.diff(xy, axis=0, append=xy[-1:] + (xy[-1:] - xy[-2:-1]))
    return xy[keep], np.arctan2(step[:, 1], step[:, 0])[keep], labels[keep], driven[keep] - driven[keep][0]


def route_track(graph, nodes, step=1.0):
    """Points every ``step`` metres along the straight roads between ``nodes``."""
    pts = []
    for a, b in zip(nodes[:-1], nodes[1:]):
        p, q = graph.nodes.loc[a, ["x", "y"]].to_numpy(float), graph.nodes.loc[b, ["x", "y"]].to_numpy(float)
        n = int(np.hypot(*(q - p)) / step)
        pts.append(p + (q - p) * np.arange(n)[:, None] / n)
    pts.append(graph.nodes.loc[[nodes[-1]], ["x", "y"]].to_numpy(float))
    return np.vstack(pts)
