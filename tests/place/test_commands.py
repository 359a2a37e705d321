"""Navigation commands of the topometric map: turn classes and the stretch before each intersection."""

from __future__ import annotations

import numpy as np

from topoloc.place.topometric_map import COMMANDS, Intersection, classify_turn, vertex_commands


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
