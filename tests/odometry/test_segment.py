"""Douglas-Peucker segmentation and token encoding of odometry tracks."""

import numpy as np
import pytest

from topoloc.encoding import encode_segments
from topoloc.geometry import quantize_angle, straight_token
from topoloc.segmentation import douglas_peucker, segment_track


def l_track(step=1.0):
    a = np.column_stack([np.zeros(101), np.arange(0, 101, step)])  # 100 m north
    b = np.column_stack([np.arange(1, 61, step), np.full(60, 100.0)])  # then 60 m east: a right turn
    return np.vstack([a, b])


def test_douglas_peucker_keeps_the_corner():
    xy = l_track()
    xy = xy + np.random.default_rng(0).normal(scale=0.3, size=xy.shape)
    assert douglas_peucker(xy, 3.0).tolist() == [0, 100, 160]


def test_l_track_tokens():
    seg = segment_track(l_track(), tolerance_m=3.0, lookahead_m=10.0)
    assert seg["corners"].tolist() == [0, 100, 160]
    assert seg["lengths"] == pytest.approx([100.0, 60.0])
    enc = encode_segments(seg["lengths"], seg["heading_start"], seg["heading_end"], 20.0, 20)
    right = quantize_angle(270.0, 20)
    s = straight_token(20)
    assert enc.tokens.tolist() == [s] * 4 + [right] + [s] * 2
    assert enc.segment.tolist() == [0] * 4 + [1] * 3


def test_standstill_frames_are_ignored():
    xy = l_track()
    xy = np.vstack([xy[:50], np.repeat(xy[50:51], 30, axis=0), xy[50:]])
    seg = segment_track(xy, tolerance_m=3.0, lookahead_m=10.0)
    assert len(seg["corners"]) == 3
    assert seg["lengths"].sum() == pytest.approx(160.0)


def rounded_right_turn(radius=12.0, step=0.5):
    """100 m north, a quarter circle of ``radius`` turning right (east), 100 m east."""
    a = np.column_stack([np.zeros(201), np.arange(0, 100.5, step)])
    phi = np.linspace(np.pi, np.pi / 2, 40)[1:]
    arc = np.column_stack([radius + radius * np.cos(phi), 100.0 + radius * np.sin(phi)])
    b = np.column_stack([np.arange(radius + step, radius + 100, step), np.full(len(np.arange(radius + step, radius + 100, step)), 100.0 + radius)])
    return np.vstack([a, arc, b])


def test_corner_skip_measures_a_rounded_turn_like_the_map():
    right = quantize_angle(270.0, 20)
    turns = {}
    for skip in (0.0, 10.0):
        seg = segment_track(rounded_right_turn(), tolerance_m=5.0, lookahead_m=10.0, corner_skip_m=skip)
        enc = encode_segments(seg["lengths"], seg["heading_start"], seg["heading_end"], 20.0, 20)
        turns[skip] = [t for t in enc.tokens.tolist() if t != straight_token(20)]
    assert turns[10.0] == [right]  # headings away from the rounded part: the map's 90 degrees
    assert turns[0.0] != [right]  # at the corner the vehicle is still turning: too small an angle
