"""Navigation commands of the topometric map: turn classes and the stretch before each intersection."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest

from tests.trajectory.trajectory_helpers import make_graph
from topoloc.place.topometric_map import (
    COMMANDS,
    Intersection,
    classify_turn,
    drive_heading_change,
    route_intersections,
    vertex_commands,
)


def test_turn_classes():
    # turning angles: 180 straight on, 90 left, 270 right (topoloc.geometry)
    assert [classify_turn(a, 45.0) for a in (180.0, 135.0, 134.9, 90.0, 225.0, 225.1, 270.0)] == [
        "straight", "straight", "left", "left", "straight", "right", "right"]


def test_commands_cover_the_distance_before_each_intersection():
    xy = np.column_stack([np.arange(100.0), np.zeros(100)])  # one frame per metre
    crossings = [Intersection(30, 1, "left", 90.0), Intersection(70, 2, "right", 270.0)]
    names = [COMMANDS[c] for c in vertex_commands(xy, crossings, 20.0)]
    assert names[:10] == ["follow"] * 10 and names[10:30] == ["left"] * 20
    assert names[30:50] == ["follow"] * 20 and names[50:70] == ["right"] * 20 and names[70:] == ["follow"] * 30
    # intersections closer together than the distance: each frame gets the next one only
    close = [COMMANDS[c] for c in vertex_commands(xy, [Intersection(30, 1, "left", 90.0),
                                                        Intersection(40, 2, "straight", 180.0)], 20.0)]
    assert close[10:30] == ["left"] * 20 and close[30:40] == ["straight"] * 10


def _drive(points: list[tuple[float, float]], edges: list[int], step_m: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Frames every ``step_m`` along the polyline ``points``, each labelled with the edge of its leg."""
    xy, label = [], []
    for (a, b), edge in zip(pairwise(points), edges):
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = int(np.hypot(*(b - a)) / step_m)
        xy.append(a + np.outer(np.arange(n) / n, b - a))
        label += [edge] * n
    return np.vstack(xy), np.array(label)


def test_heading_change_of_a_drive_is_signed_and_ignores_standstill():
    xy, _ = _drive([(0, 0), (30, 0), (30, -30)], [0, 1])
    assert drive_heading_change(xy, 0.0, 60.0) == pytest.approx(-90.0, abs=1.0)  # east, then south: right
    assert drive_heading_change(xy[::-1], 0.0, 60.0) == pytest.approx(90.0, abs=1.0)
    assert drive_heading_change(xy, 0.0, 25.0) == pytest.approx(0.0, abs=1e-6)  # before the corner
    stopped = np.vstack([xy[:20], np.repeat(xy[20:21], 15, axis=0), xy[20:]])  # the vehicle stands for 15 frames
    assert drive_heading_change(stopped, 0.0, 60.0) == pytest.approx(-90.0, abs=1.0)


def test_a_bend_into_a_junction_crossed_straight_on_is_the_bends_turn():
    # West to east, a 90 deg bend to the south 12 m before junction J, then straight on through J. The junction's
    # own angle (10 m back along the entry road) is straight on; the vehicle, told 20 m before J, turns right.
    coords = {0: (-60.0, 0.0), 1: (0.0, 0.0), 2: (0.0, -12.0), 3: (0.0, -60.0), 4: (-40.0, -12.0), 5: (40.0, -12.0)}
    graph = make_graph(coords, [(0, 1), (1, 2), (2, 3), (4, 2), (2, 5)])
    xy, edge = _drive([coords[0], coords[1], coords[2], coords[3]], [0, 1, 2])
    (bend,) = route_intersections(graph, edge, xy, 10.0, 45.0, 20.0)
    assert bend.node == 2 and bend.command == "right" and bend.angle_deg == pytest.approx(270.0, abs=1.0)
    commands = [COMMANDS[c] for c in vertex_commands(xy, [bend], 20.0)]
    assert commands[bend.frame - 1] == "right" and commands[bend.frame] == "follow"
    # a straight approach: the junction's own turn (north then east: right; west to east: straight on)
    xy, edge = _drive([coords[3], coords[2], coords[5]], [2, 4])
    assert [c.command for c in route_intersections(graph, edge, xy, 10.0, 45.0, 20.0)] == ["right"]
    xy, edge = _drive([coords[4], coords[2], coords[5]], [3, 4])
    assert [c.command for c in route_intersections(graph, edge, xy, 10.0, 45.0, 20.0)] == ["straight"]
