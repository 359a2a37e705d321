import numpy as np
import pytest

from topoloc.encoding import encode_segments, polyline_end_headings, turning_angle_from_headings


def test_encoding_of_a_drive_with_a_left_then_a_right_turn():
    # East 50 m, left turn, north 30 m, right turn, east 10 m; virtual nodes every 20 m.
    drive = encode_segments([50.0, 30.0, 10.0], [0.0, 90.0, 0.0], [0.0, 90.0, 0.0], spacing_m=20.0, bins=20)
    # 2 virtual nodes on the first road, left (5), 1 virtual node, right (15), none on the last.
    assert drive.tokens.tolist() == [10, 10, 5, 10, 15]
    assert drive.segment.tolist() == [0, 0, 1, 1, 2]


def test_turn_uses_end_and_start_headings_not_chords():
    # A road that bends: it leaves heading 0 and arrives heading 80; the next leaves at 80: straight on.
    drive = encode_segments([30.0, 30.0], [0.0, 80.0], [80.0, 80.0], spacing_m=100.0, bins=20)
    assert drive.tokens.tolist() == [10]
    assert drive.segment.tolist() == [1]


def test_heading_wraparound():
    assert turning_angle_from_headings(170.0, -170.0) == pytest.approx(160.0)  # 20 degrees left
    assert turning_angle_from_headings(-170.0, 170.0) == pytest.approx(200.0)  # 20 degrees right


def test_end_headings_of_a_curved_polyline():
    arc = np.array([(0.0, 0.0), (10.0, 0.0), (20.0, 10.0), (20.0, 20.0)])
    start, end = polyline_end_headings(arc, lookahead_m=5.0)
    assert start == pytest.approx(0.0)
    assert end == pytest.approx(90.0)


def test_mismatched_lengths_are_rejected():
    with pytest.raises(ValueError):
        encode_segments([1.0, 2.0], [0.0], [0.0, 0.0], 10.0, 20)
