"""Seeded textures: building facades, the road surface, fine ground grain and the sky.

* A **facade** is a ``TILE_H`` x ``TILE_W`` tile (0.1 m texels: 32 m tall, repeating every 25.6 m along
  the walls) drawn from the building's own seed: plaster colour, floor heights, bays of windows with
  frames, sills and glass of varied brightness, a ground floor of shop windows, doors and coloured sign
  bands, cornices, and weathering noise. A second, grey tile marks the windows that are lit at night.
  The tile repeats seamlessly along the wall; row ``TILE_H - 1`` is at the ground.
* The **road surface** is drawn from the road graph into world-anchored rasters (0.1 m texels): paving,
  sidewalks, asphalt by road class, dashed centre lines on two-way roads, edge lines, zebra crossings.
* The **grain** is a periodic tile of multi-scale noise (2 cm texels, 20.48 m period) that multiplies the
  road surface, so the ground near the car has texture for feature tracking.
* The **sky** is a 360-degree panorama per condition: a vertical gradient, periodic clouds, a sun glow.

Everything is a pure function of its seed and arguments.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import pandas as pd
from numpy.typing import NDArray

TEXEL_M = 0.1
TILE_W, TILE_H = 256, 320
GRAIN_TEXEL_M, GRAIN_SIZE = 0.02, 1024
SKY_WIDTH = 2048

# Plaster and brick colours (BGR) of facades.
_PALETTE = np.array([[172, 196, 214], [150, 182, 205], [120, 160, 200], [200, 205, 210], [185, 190, 190],
                     [90, 110, 160], [70, 80, 130], [160, 175, 150], [170, 160, 140], [120, 130, 135],
                     [130, 170, 175], [205, 215, 225], [100, 140, 185], [150, 150, 170]], dtype=np.float32)
_SIGNS = np.array([[40, 40, 200], [200, 80, 30], [30, 150, 40], [30, 180, 220], [160, 40, 140], [30, 30, 30],
                   [220, 220, 220]], dtype=np.float32)

ROAD_WIDTH_M = {"motorway": 14.0, "trunk": 12.0, "primary": 12.0, "secondary": 10.0, "tertiary": 9.0,
                "unclassified": 7.0, "residential": 7.0, "living_street": 5.0, "service": 4.5, "road": 6.0}
#: Width of one traffic lane, for roads tagged with ``lanes`` only, metres.
LANE_WIDTH_M = 3.25
#: A ``width`` tag outside this range (metres) is not taken for a carriageway (it would be a typo or the whole street).
TAGGED_WIDTH_M = (4.0, 25.0)
PAVING, SIDEWALK, ASPHALT, MARKING = (132, 136, 138), (160, 162, 163), (82, 82, 84), (225, 228, 230)
SIDEWALK_M = 3.0
#: Carriageways at least this wide get edge lines, and a dashed centre line when two-way.
MARKED_WIDTH_M = 6.0


def road_width(highway: str) -> float:
    """Carriageway width in metres of an OSM highway class (``*_link`` as 7 m)."""
    return ROAD_WIDTH_M.get(highway, 7.0 if highway.endswith("_link") else 6.0)


def carriageway_width(highway: str, lanes: float = float("nan"), width_m: float = float("nan")) -> float:
    """Carriageway width in metres of a road: its ``width`` tag (:data:`TAGGED_WIDTH_M` bounds it), else its ``lanes``
    tag times :data:`LANE_WIDTH_M` (within :data:`TAGGED_WIDTH_M`'s bounds too), else the class default
    (:func:`road_width`)."""
    lo, hi = TAGGED_WIDTH_M
    if np.isfinite(width_m) and lo <= width_m <= hi:
        return float(width_m)
    if np.isfinite(lanes) and lanes >= 1:
        return float(np.clip(lanes * LANE_WIDTH_M, lo, hi))
    return road_width(highway)


def edge_widths(edges: pd.DataFrame) -> NDArray[np.float64]:
    """:func:`carriageway_width` of every row of a road graph's edge table (``highway``, ``lanes``, ``width_m``)."""
    return np.array([carriageway_width(str(h), float(n), float(w))
                     for h, n, w in zip(edges.highway, edges.lanes, edges.width_m)])


def has_centre_line(width_m: float, two_way: bool) -> bool:
    """Whether a carriageway is drawn with a dashed centre line: two-way and at least :data:`MARKED_WIDTH_M` wide.
    A driver keeps right of such a line and drives in the middle of any other road (:mod:`topoloc.drive.drive_route`)."""
    return bool(two_way and width_m >= MARKED_WIDTH_M)


def _periodic_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float) -> NDArray[np.float32]:
    """Gaussian-filtered white noise that wraps around in both axes, scaled to unit standard deviation."""
    white = rng.standard_normal(shape)
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    smooth = np.fft.irfft2(np.fft.rfft2(white) * np.exp(-2 * (np.pi * sigma) ** 2 * (fx**2 + fy**2)), s=shape)
    return (smooth / (smooth.std() + 1e-12)).astype(np.float32)


@lru_cache(maxsize=4)
def _facade_noise(seed: int) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Fine and coarse periodic noise (2 * TILE_H rows, TILE_W columns) that facades crop from."""
    rng = np.random.default_rng([seed, 17])
    shape = (2 * TILE_H, TILE_W)
    return _periodic_noise(rng, shape, 0.7), _periodic_noise(rng, shape, 12.0)


def facade_texture(key: int, seed: int) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Facade tile (TILE_H, TILE_W, 3) BGR and its night window-glow mask (TILE_H, TILE_W) for building ``key``."""
    rng = np.random.default_rng([seed, 1, int(key)])
    base = np.clip(_PALETTE[rng.integers(len(_PALETTE))] + rng.normal(0, 12, 3), 30, 240)
    img = np.empty((TILE_H, TILE_W, 3), np.float32)
    img[:] = base
    glow = np.zeros((TILE_H, TILE_W), np.float32)
    bays = int(rng.integers(5, 11))
    bay = TILE_W / bays
    ground = rng.uniform(3.6, 4.8) / TEXEL_M
    floor = rng.uniform(2.9, 3.6) / TEXEL_M
    win_w = bay * rng.uniform(0.32, 0.6)
    win_h = floor * rng.uniform(0.42, 0.62)
    frame = np.clip(base * rng.uniform(0.5, 1.3) + rng.normal(0, 20, 3), 10, 250)
    glass = np.array([70, 60, 50], np.float32) * rng.uniform(0.6, 1.4)
    lit_share = rng.uniform(0.15, 0.55)
    bottom = TILE_H - 1
    # Plinth and ground floor: shop windows, doors, plain wall; a sign band over each shop.
    plinth = np.clip(base * rng.uniform(0.55, 0.9), 10, 255)
    cv2.rectangle(img, (0, int(bottom - ground)), (TILE_W - 1, bottom), plinth.tolist(), -1)
    for i in range(bays):
        x0 = i * bay
        kind = rng.choice(4, p=[0.45, 0.2, 0.25, 0.1])
        if kind == 0:  # shop window with sign
            w = bay * rng.uniform(0.7, 0.9)
            l, r = int(x0 + (bay - w) / 2), int(x0 + (bay + w) / 2)
            top = int(bottom - ground * rng.uniform(0.62, 0.75))
            cv2.rectangle(img, (l, top), (r, bottom - 3), (glass * rng.uniform(0.7, 1.6)).tolist(), -1)
            cv2.rectangle(img, (l, top), (r, bottom - 3), frame.tolist(), 1)
            sign = _SIGNS[rng.integers(len(_SIGNS))]
            cv2.rectangle(img, (l, int(top - 7)), (r, top - 2), sign.tolist(), -1)
            glow[top:bottom - 3, l:r + 1] = rng.uniform(0.3, 0.6) if rng.random() < 0.6 else 0.0
        elif kind == 1:  # door
            w = 1.2 / TEXEL_M
            l = int(x0 + rng.uniform(0.1, 0.9) * (bay - w))
            cv2.rectangle(img, (l, int(bottom - 2.4 / TEXEL_M)), (int(l + w), bottom), (base * 0.35).tolist(), -1)
            cv2.rectangle(img, (l, int(bottom - 2.4 / TEXEL_M)), (int(l + w), bottom), frame.tolist(), 1)
        elif kind == 2:  # small window
            l, r = int(x0 + (bay - win_w) / 2), int(x0 + (bay + win_w) / 2)
            top = int(bottom - ground * 0.75)
            cv2.rectangle(img, (l, top), (r, int(top + win_h)), (glass * rng.uniform(0.6, 1.5)).tolist(), -1)
            cv2.rectangle(img, (l, top), (r, int(top + win_h)), frame.tolist(), 1)
    # Upper floors: a cornice line, then one window per bay (a few blind ones).
    cornice = np.clip(base * rng.uniform(0.75, 1.2), 0, 255).tolist()
    y = bottom - ground
    while y - floor > 0:
        cv2.rectangle(img, (0, int(y - 1)), (TILE_W - 1, int(y)), cornice, -1)
        sill = int(y - floor * 0.25)
        for i in range(bays):
            if rng.random() < 0.06:
                continue
            l, r = int(i * bay + (bay - win_w) / 2), int(i * bay + (bay + win_w) / 2)
            top = int(sill - win_h)
            shade = glass * rng.uniform(0.5, 1.7)
            cv2.rectangle(img, (l, top), (r, sill), shade.tolist(), -1)
            if rng.random() < 0.3:  # curtain in the upper part
                cv2.rectangle(img, (l + 1, top + 1), (r - 1, int(top + win_h * rng.uniform(0.2, 0.5))),
                              (rng.uniform(120, 230, 3)).tolist(), -1)
            cv2.rectangle(img, (l, top), (r, sill), frame.tolist(), 1)
            cv2.line(img, ((l + r) // 2, top), ((l + r) // 2, sill), frame.tolist(), 1)
            cv2.rectangle(img, (l - 1, sill), (r + 1, sill + 1), cornice, -1)
            if rng.random() < lit_share:
                glow[top + 1:sill, l + 1:r] = rng.uniform(0.4, 0.9)
        y -= floor
    fine, coarse = _facade_noise(seed)
    oy, ox = int(rng.integers(TILE_H)), int(rng.integers(TILE_W))
    fine = np.roll(fine[oy:oy + TILE_H], ox, axis=1)
    coarse = np.roll(coarse[oy:oy + TILE_H], ox, axis=1)
    img *= (1.0 + 0.09 * coarse)[..., None]
    img += (7.0 * fine)[..., None]
    return np.clip(img, 0, 255).astype(np.uint8), np.clip(glow * 255, 0, 255).astype(np.uint8)


@lru_cache(maxsize=4)
def grain_tile(seed: int) -> NDArray[np.float32]:
    """Periodic multiplicative ground grain (GRAIN_SIZE square, mean 1): fine grit, patches and stains."""
    rng = np.random.default_rng([seed, 2])
    shape = (GRAIN_SIZE, GRAIN_SIZE)
    tile = 0.07 * _periodic_noise(rng, shape, 0.8) + 0.08 * _periodic_noise(rng, shape, 5.0) \
        + 0.07 * _periodic_noise(rng, shape, 25.0)
    return np.clip(1.0 + tile, 0.6, 1.4).astype(np.float32)


@dataclass(frozen=True)
class Road:
    """A road to draw: polyline (n, 2) in map metres, carriageway width, two-way flag, and marking trims."""

    coords: NDArray[np.float64]
    width: float
    two_way: bool
    trim_start_m: float = 0.0
    trim_end_m: float = 0.0


def _to_px(xy: NDArray[np.float64], x0: float, y1: float) -> NDArray[np.int32]:
    """Map metres to raster pixels in 1/4-pixel fixed point (``shift=2``)."""
    return np.round(np.column_stack([(xy[:, 0] - x0) / TEXEL_M, (y1 - xy[:, 1]) / TEXEL_M]) * 4).astype(np.int32)


def _pieces(coords: NDArray[np.float64], start: float, stop: float, on: float, off: float) -> list[NDArray[np.float64]]:
    """Sub-polylines of ``coords`` from ``start`` to ``stop`` metres: ``on`` metres drawn, ``off`` skipped."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
    out = []
    s = start
    while s < stop - 0.1:
        e = min(s + on, stop)
        inner = (cum > s) & (cum < e)
        pts = np.vstack([[np.interp(s, cum, coords[:, 0]), np.interp(s, cum, coords[:, 1])], coords[inner],
                         [np.interp(e, cum, coords[:, 0]), np.interp(e, cum, coords[:, 1])]])
        out.append(pts)
        s = e + off
    return out


def _offset(coords: NDArray[np.float64], d: float) -> NDArray[np.float64]:
    """Polyline shifted ``d`` metres to its right (per-vertex normals)."""
    tangent = np.gradient(coords, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
    return coords + d * np.column_stack([tangent[:, 1], -tangent[:, 0]])


def draw_ground(roads: list[Road], x0: float, y1: float, shape: tuple[int, int]) -> NDArray[np.uint8]:
    """The road surface (shape[0], shape[1], 3) BGR whose pixel (0, 0) has its corner at map (x0, y1)."""
    img = np.empty((*shape, 3), np.uint8)
    img[:] = PAVING
    aa = cv2.LINE_AA
    for road in roads:
        pts = _to_px(road.coords, x0, y1)
        cv2.polylines(img, [pts], False, SIDEWALK, max(1, round((road.width + 2 * SIDEWALK_M) / TEXEL_M)), aa, 2)
    for road in roads:
        pts = _to_px(road.coords, x0, y1)
        cv2.polylines(img, [pts], False, (70, 70, 72), max(1, round((road.width + 0.4) / TEXEL_M)), aa, 2)
        cv2.polylines(img, [pts], False, ASPHALT, max(1, round(road.width / TEXEL_M)), aa, 2)
    for road in roads:
        length = float(np.hypot(*np.diff(road.coords, axis=0).T).sum())
        start, stop = road.trim_start_m, length - road.trim_end_m
        if stop - start < 2.0:
            continue
        thin = max(1, round(0.15 / TEXEL_M))
        if has_centre_line(road.width, road.two_way):
            for piece in _pieces(road.coords, start, stop, 3.0, 5.0):
                cv2.polylines(img, [_to_px(piece, x0, y1)], False, MARKING, thin, aa, 2)
        if road.width >= MARKED_WIDTH_M:
            for side in (-1.0, 1.0):
                edge = _offset(road.coords, side * (road.width / 2 - 0.5))
                for piece in _pieces(edge, start, stop, 1e9, 0.0):
                    cv2.polylines(img, [_to_px(piece, x0, y1)], False, MARKING, thin, aa, 2)
        if road.width >= 7.0:  # zebra crossings where the markings stop at a junction
            for at, trim in ((start - 3.5, road.trim_start_m), (stop + 0.5, road.trim_end_m)):
                if trim <= 0:
                    continue
                for lateral in np.arange(-road.width / 2 + 0.75, road.width / 2 - 0.5, 1.0):
                    for piece in _pieces(_offset(road.coords, lateral), at, at + 3.0, 1e9, 0.0):
                        cv2.polylines(img, [_to_px(piece, x0, y1)], False, MARKING, round(0.5 / TEXEL_M), aa, 2)
    return img


def sky_panorama(rows: int, elevations_deg: NDArray[np.float64], zenith: tuple[float, float, float],
                 horizon: tuple[float, float, float], clouds: float, cloud_color: tuple[float, float, float],
                 sun: tuple[float, float, float, float] | None, seed: int) -> NDArray[np.float32]:
    """Sky (rows, SKY_WIDTH, 3) float BGR in 0..1; column j looks at azimuth ``360 j / SKY_WIDTH`` degrees.

    ``elevations_deg`` gives the elevation of each row; ``sun`` is (azimuth_deg, elevation_deg, glow,
    glow_width_deg) with the azimuth counter-clockwise from east, or None.
    """
    t = np.clip(np.asarray(elevations_deg, float) / 35.0, 0.0, 1.0) ** 0.6
    sky = (1 - t)[:, None, None] * np.asarray(horizon) + t[:, None, None] * np.asarray(zenith)
    sky = np.broadcast_to(sky, (rows, SKY_WIDTH, 3)).astype(np.float32).copy()
    if clouds > 0:
        rng = np.random.default_rng([seed, 3])
        noise = _periodic_noise(rng, (max(rows, 1), SKY_WIDTH), 6.0)
        cover = np.clip((noise + 1.0 - 2.0 * (1.0 - clouds)) * 0.8, 0.0, 1.0) * clouds
        sky += cover[..., None] * (np.asarray(cloud_color, np.float32) - sky)
    if sun is not None:
        az, el, glow, width = sun
        azimuths = np.arange(SKY_WIDTH) * 360.0 / SKY_WIDTH
        daz = (azimuths - az + 180.0) % 360.0 - 180.0
        dist = np.hypot(daz[None, :], np.asarray(elevations_deg, float)[:, None] - el)
        sky += (glow * np.exp(-(dist / width) ** 2))[..., None].astype(np.float32) * np.array([0.55, 0.8, 1.0], np.float32)
    return np.clip(sky, 0.0, 1.5)
