"""Token encoding of a drive: turning-angle tokens at turns, straight tokens at virtual nodes.

A drive is a sequence of *segments* (map roads, or odometry stretches between
Douglas-Peucker corners), each with its length along the way and its travel
heading where it starts and where it ends. The token sequence is::

    virtual nodes of segment 0, turn(0 -> 1), virtual nodes of segment 1, turn(1 -> 2), ...

with the label of each token the index of the segment the vehicle is on after
that step (the segment on which the last turn occurred). Training data (map
routes) and test data (odometry) go through this one function, so they share
one convention; see :mod:`topoloc.geometry` for angles, bins and spacing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from topoloc.geometry import point_along, quantize_angle, straight_token, virtual_node_count


@dataclass(frozen=True)
class EncodedDrive:
    """Tokens of a drive and, per token, the index of its segment."""

    tokens: NDArray[np.int64]
    segment: NDArray[np.int64]


def heading_deg(start: ArrayLike, end: ArrayLike) -> float:
    """Heading of travel from ``start`` to ``end``, counter-clockwise from +x, in degrees."""
    dx, dy = np.asarray(end, dtype=float) - np.asarray(start, dtype=float)
    return float(np.degrees(np.arctan2(dy, dx)))


def turning_angle_from_headings(heading_out_prev: ArrayLike, heading_in_next: ArrayLike) -> NDArray[np.float64]:
    """Local turning angle(s) ``phi`` in [0, 360) between an arrival and a departure heading."""
    delta = np.mod(np.asarray(heading_in_next, float) - np.asarray(heading_out_prev, float) + 180.0, 360.0) - 180.0
    delta = np.where(delta <= -180.0, 180.0, delta)
    return np.mod(180.0 - delta, 360.0)


def encode_segments(
    lengths_m: ArrayLike,
    heading_start: ArrayLike,
    heading_end: ArrayLike,
    spacing_m: float,
    bins: int,
) -> EncodedDrive:
    """Encode consecutive segments (lengths and start/end headings in degrees) as tokens and segment labels."""
    lengths = np.asarray(lengths_m, dtype=float)
    starts = np.asarray(heading_start, dtype=float)
    ends = np.asarray(heading_end, dtype=float)
    if not (lengths.shape == starts.shape == ends.shape) or lengths.ndim != 1:
        raise ValueError("lengths_m, heading_start and heading_end must be 1-D arrays of one length")
    turns = quantize_angle(turning_angle_from_headings(ends[:-1], starts[1:]), bins) if len(lengths) > 1 else []
    straight = straight_token(bins)
    tokens: list[int] = []
    segment: list[int] = []
    for index, length in enumerate(lengths):
        if index > 0:
            tokens.append(int(np.atleast_1d(turns)[index - 1]))
            segment.append(index)
        count = virtual_node_count(float(length), spacing_m)
        tokens.extend([straight] * count)
        segment.extend([index] * count)
    return EncodedDrive(np.asarray(tokens, dtype=np.int64), np.asarray(segment, dtype=np.int64))


def polyline_end_headings(coords: ArrayLike, lookahead_m: float) -> tuple[float, float]:
    """Travel headings at the start and end of a polyline, over ``lookahead_m`` (at most half its length).

    Using the geometry near the ends, not the chord, gives the direction in
    which a curved road leaves and enters its intersections.
    """
    pts = np.asarray(coords, dtype=float)
    length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
    reach = min(lookahead_m, length / 2.0) if length > 0 else 0.0
    start = heading_deg(pts[0], point_along(pts, reach))
    end = heading_deg(point_along(pts, length - reach), pts[-1])
    return start, end
