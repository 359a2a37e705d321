import numpy as np
import pytest

from topoloc.geometry import (
    bin_centre,
    heading_change,
    point_along,
    polyline_turning_angles,
    quantize_angle,
    straight_token,
    turning_angle,
    virtual_node_count,
    virtual_node_offsets,
)

# Driving north into the node at the origin.
PREV, CUR = (0.0, -10.0), (0.0, 0.0)


@pytest.mark.parametrize(
    ("nxt", "phi", "token"),
    [
        ((0.0, 10.0), 180.0, 10),  # straight on
        ((-10.0, 0.0), 90.0, 5),  # left
        ((10.0, 0.0), 270.0, 15),  # right
        ((0.0, -10.0), 0.0, 0),  # U-turn
        ((-10.0, 10.0), 135.0, 8),  # half left: 135 / 18 = 7.5 -> bin 8 starts at 135
        ((10.0, 10.0), 225.0, 13),  # half right: 225 / 18 = 12.5 -> bin 13 starts at 225
    ],
)
def test_turning_angle_and_token(nxt, phi, token):
    assert turning_angle(PREV, CUR, nxt) == pytest.approx(phi, abs=1e-9)
    assert quantize_angle(turning_angle(PREV, CUR, nxt), 20) == token


def test_angle_is_measured_relative_to_the_entry_direction():
    # The same left turn entered heading east gives the same local angle.
    assert turning_angle((-5.0, 0.0), (0.0, 0.0), (0.0, 5.0)) == pytest.approx(90.0)
    assert heading_change((-5.0, 0.0), (0.0, 0.0), (0.0, 5.0)) == pytest.approx(90.0)
    assert heading_change(PREV, CUR, (0.0, -10.0)) == 180.0  # U-turn folds onto +180


def test_straight_is_the_centre_of_its_bin():
    assert straight_token(20) == 10
    assert bin_centre(10, 20) == pytest.approx(180.0)
    # Noise of +-8.9 degrees around straight keeps the straight token; 9 degrees is the bin edge.
    assert quantize_angle([171.1, 188.9], 20).tolist() == [10, 10]
    assert quantize_angle([170.99, 189.0], 20).tolist() == [9, 11]


def test_bin_edges_are_half_open_and_wrap():
    width = 18.0
    assert quantize_angle(9.0 - 1e-9, 20) == 0
    assert quantize_angle(9.0, 20) == 1
    assert quantize_angle(351.0, 20) == 0  # bin 0 wraps around 0 / 360
    assert quantize_angle(351.0 - 1e-9, 20) == 19
    assert quantize_angle(360.0, 20) == 0
    centres = bin_centre(np.arange(20), 20)
    assert np.array_equal(quantize_angle(centres, 20), np.arange(20))
    assert np.allclose(np.diff(centres[1:]), width)


def test_odd_bin_counts_keep_straight_centred():
    assert straight_token(5) == 2
    assert quantize_angle(180.0, 5) == 2
    assert bin_centre(2, 5) == pytest.approx(180.0)
    assert quantize_angle(180.0 + 36.0, 5) == 3  # edge of the straight bin at 180 + 72 / 2


def test_polyline_turning_angles():
    square = np.array([(0, 0), (10, 0), (10, 10), (0, 10)], dtype=float)
    assert polyline_turning_angles(square).tolist() == pytest.approx([90.0, 90.0])
    assert polyline_turning_angles(square[:2]).size == 0


def test_virtual_nodes_every_spacing_strictly_inside():
    assert virtual_node_count(0.0, 20) == 0
    assert virtual_node_count(19.9, 20) == 0
    assert virtual_node_count(20.0, 20) == 0  # a node exactly at the end is the real node
    assert virtual_node_count(20.5, 20) == 1
    assert virtual_node_count(100.0, 20) == 4
    assert virtual_node_offsets(65.0, 20).tolist() == [20.0, 40.0, 60.0]
    with pytest.raises(ValueError):
        virtual_node_count(10.0, 0.0)


def test_point_along_polyline():
    line = np.array([(0, 0), (10, 0), (10, 10)], dtype=float)
    assert point_along(line, 15.0).tolist() == [10.0, 5.0]
    assert point_along(line, -1.0).tolist() == [0.0, 0.0]
    assert point_along(line, 99.0).tolist() == [10.0, 10.0]
