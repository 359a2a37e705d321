"""Segmentation of an odometry track into turns and distances, and its token encoding.

A track (map positions per frame) is simplified with Douglas-Peucker; its corners cut it into segments.
Each segment's length is the track's path length between its corners, its start/end headings the
direction of travel over a lookahead after its first / before its last corner, leaving out a stretch
next to each corner where a vehicle is still rounding it (:func:`track_end_headings`). The segments go
through :func:`topoloc.encoding.encode_segments`, the same function as the training routes, so train and
test tokens share one convention; :func:`encode_track` also gives each token's place and frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.encoding import EncodedDrive, encode_segments, heading_deg, polyline_end_headings
from topoloc.geometry import point_along


def douglas_peucker(points: NDArray[np.float64], tolerance: float) -> NDArray[np.int64]:
    """Indices of the points kept by Douglas-Peucker (always the first and last), iteratively."""
    pts = np.asarray(points, float)
    n = len(pts)
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, b = pts[i], pts[j]
        seg = pts[i + 1:j]
        d = b - a
        norm = np.hypot(*d)
        if norm > 1e-12:
            dist = np.abs(d[0] * (seg[:, 1] - a[1]) - d[1] * (seg[:, 0] - a[0])) / norm
        else:
            dist = np.hypot(seg[:, 0] - a[0], seg[:, 1] - a[1])
        k = int(np.argmax(dist))
        if dist[k] > tolerance:
            m = i + 1 + k
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return np.flatnonzero(keep)


def track_end_headings(coords: NDArray[np.float64], lookahead_m: float, skip_m: float = 0.0) -> tuple[float, float]:
    """Travel headings at the start and end of a track piece over ``lookahead_m``, ``skip_m`` away from its ends.

    Like :func:`topoloc.encoding.polyline_end_headings` (the same with ``skip_m = 0``), but leaving out
    ``skip_m`` (at most a quarter of the piece) next to each end first: a vehicle rounds a corner, so the
    track right at a corner still turns, where a map road drawn through its intersection node does not.
    """
    if skip_m <= 0:
        return polyline_end_headings(coords, lookahead_m)
    pts = np.asarray(coords, dtype=float)
    length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
    skip = min(skip_m, length / 4.0)
    reach = min(lookahead_m, length / 2.0 - skip)
    start = heading_deg(point_along(pts, skip), point_along(pts, skip + reach))
    end = heading_deg(point_along(pts, length - skip - reach), point_along(pts, length - skip))
    return start, end


def segment_track(xy: NDArray[np.float64], tolerance_m: float, lookahead_m: float, min_step_m: float = 0.05,
                  corner_skip_m: float = 0.0) -> dict[str, NDArray]:
    """DP corners (frame indices) and per-segment length and start/end headings of a track (n, 2).

    Headings are measured over ``lookahead_m`` after skipping ``corner_skip_m`` next to each corner
    (:func:`track_end_headings`).
    """
    xy = np.asarray(xy, float)
    step = np.hypot(*np.diff(xy, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(step)])
    # Standstill frames carry no direction: simplify the moving frames only, map back to frame indices.
    moving = np.concatenate([[True], step > min_step_m])
    moving[-1] = True
    idx = np.flatnonzero(moving)
    corners = idx[douglas_peucker(xy[idx], tolerance_m)]
    lengths, h0, h1 = [], [], []
    for a, b in zip(corners[:-1], corners[1:]):
        piece = xy[a:b + 1][moving[a:b + 1]]
        if len(piece) < 2:
            piece = xy[[a, b]]
        start, end = track_end_headings(piece, lookahead_m, corner_skip_m)
        lengths.append(cum[b] - cum[a])
        h0.append(start)
        h1.append(end)
    return {"corners": corners, "cum": cum, "lengths": np.asarray(lengths), "heading_start": np.asarray(h0),
            "heading_end": np.asarray(h1)}


@dataclass(frozen=True)
class EncodedTrack:
    """A track's segmentation (:func:`segment_track`), its tokens, and per token its kind, place and frame."""

    segments: dict[str, NDArray]
    encoded: EncodedDrive
    kind: list[str]
    place_m: NDArray[np.float64]
    frame: NDArray[np.int64]


def token_places(encoded: EncodedDrive, starts_m: NDArray[np.float64], lengths_m: NDArray[np.float64],
                 spacing_m: NDArray[np.float64], turn_label_offset_m: float) -> tuple[NDArray[np.float64], list[str]]:
    """Place of each token (metres along the track) and its kind (``virtual`` or ``turn``).

    ``starts_m`` and ``lengths_m`` are per segment, ``spacing_m`` the virtual-node spacing per segment.
    """
    place = np.empty(len(encoded.tokens))
    kind = []
    virtual_index = 0
    for t, s in enumerate(encoded.segment):
        if s > 0 and (t == 0 or encoded.segment[t - 1] != s):  # the first token of segments 1.. is the turn into it
            place[t] = starts_m[s] + min(turn_label_offset_m, lengths_m[s] / 2.0)
            kind.append("turn")
            virtual_index = 0
        else:
            virtual_index = virtual_index + 1 if t > 0 and encoded.segment[t - 1] == s else 1
            place[t] = starts_m[s] + virtual_index * spacing_m[s]
            kind.append("virtual")
    return place, kind


def encode_track(xy: NDArray[np.float64], spacing_m: float, bins: int, tolerance_m: float, lookahead_m: float,
                 turn_label_offset_m: float, corner_skip_m: float = 0.0) -> EncodedTrack:
    """Segment a track ``(n, 2)`` and encode it; each token's place (metres along the track) and frame.

    A virtual-node token sits ``k * spacing`` along its segment; a turn token
    ``turn_label_offset_m`` past its corner (at most half the segment), on the road taken after the turn.
    """
    seg = segment_track(xy, tolerance_m, lookahead_m, corner_skip_m=corner_skip_m)
    encoded = encode_segments(seg["lengths"], seg["heading_start"], seg["heading_end"], spacing_m, bins)
    corners, cum = seg["corners"], seg["cum"]
    place, kind = token_places(encoded, cum[corners], seg["lengths"], np.full(len(seg["lengths"]), spacing_m), turn_label_offset_m)
    frame_of = np.clip(np.searchsorted(cum, place), 0, len(xy) - 1)
    return EncodedTrack(seg, encoded, kind, place, frame_of)


#: The continuous per-token features of :func:`token_features`, in column order.
TOKEN_FEATURES = ("distance", "turn", "heading_change")


def token_features(track: EncodedTrack, yaw: NDArray[np.float64], spacing_m: float) -> NDArray[np.float32]:
    """Continuous features ``(T, 3)`` of each token of ``track``, the metric information a token rounds away.

    Columns (:data:`TOKEN_FEATURES`): metres driven since the previous token (since the first frame for the
    first token) over ``spacing_m``; the unquantized turning angle of a turn token (signed degrees, left
    positive, over 90; 0 at virtual nodes); the change of the odometry heading ``yaw`` (radians per frame)
    since the previous token (degrees over 90), which keeps the bends that Douglas-Peucker leaves out.
    """
    place = np.asarray(track.place_m, float)
    distance = np.diff(place, prepend=0.0) / spacing_m
    turn = np.zeros(len(place))
    seg = track.segments
    starts = np.flatnonzero(np.asarray(track.kind) == "turn")
    if len(starts):
        s = track.encoded.segment[starts]
        delta = np.mod(seg["heading_start"][s] - seg["heading_end"][s - 1] + 180.0, 360.0) - 180.0
        turn[starts] = delta / 90.0
    unwrapped = np.unwrap(np.asarray(yaw, float))
    at = unwrapped[np.asarray(track.frame)]
    change = np.degrees(np.diff(at, prepend=unwrapped[0])) / 90.0
    return np.column_stack([distance, turn, change]).astype(np.float32)


def encode_odometry(xy: NDArray[np.float64], yaw: NDArray[np.float64], spacing_m: float, bins: int,
                    conf: Mapping[str, Any]) -> tuple[EncodedTrack, NDArray[np.float32]]:
    """An odometry track ``xy`` / ``yaw`` segmented and encoded as the ``segment_trajectory`` stage does it
    (``conf``: the ``segmentation`` and ``encoding`` slices), and its tokens' :func:`token_features`."""
    seg, enc = conf["segmentation"], conf["encoding"]
    track = encode_track(xy, spacing_m, bins, float(seg["tolerance_m"]), float(enc["heading_lookahead_m"]),
                         float(seg["turn_label_offset_m"]), float(seg["corner_skip_m"]))
    return track, token_features(track, yaw, spacing_m)
