"""Images of a :class:`~topoloc.render.scene.Scene` seen by a stereo rig under a condition.

Per image: cast one ray per column against the walls (:mod:`~topoloc.render.raycast`); a pixel of that
column is wall where its ray meets the wall between the ground and the wall's top, ground below (each
row below the horizon meets the ground at the depth ``camera_height * f / (v - cy)``: inverse perspective
mapping into the road-surface raster and the grain tile), and sky above (a panorama indexed by azimuth).
Then the condition's lighting, fog, colour, lens weather and sensor model are applied
(:mod:`~topoloc.render.conditions`). Everything is vectorised over pixels; per frame the only
Python-level work is a few dozen array operations. The output is deterministic for a seed: the noise and
rain of an image depend only on (seed, frame, camera).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from topoloc.render.conditions import Condition
from topoloc.render.raycast import cast
from topoloc.render.rig import StereoRig
from topoloc.render.scene import Scene
from topoloc.render.textures import (
    GRAIN_SIZE,
    GRAIN_TEXEL_M,
    PAVING,
    SKY_WIDTH,
    TEXEL_M,
    TILE_H,
    TILE_W,
    sky_panorama,
)

NOISE_BANK = 16
DETAIL_NEAR_M, DETAIL_FAR_M = 25.0, 60.0
MAX_GROUND_M = 1000.0
_GROUND_MEAN = np.array([105.0, 106.0, 108.0], np.float32) / 255.0


class Renderer:
    """Renders a scene for a rig and a condition; build one per condition (the set-up is cheap)."""

    def __init__(self, scene: Scene, rig: StereoRig, condition: Condition, seed: int, view_distance_m: float) -> None:
        self.scene, self.rig, self.cond, self.seed, self.view = scene, rig, condition, int(seed), float(view_distance_m)
        c = condition
        self.k = rig.column_slopes().astype(np.float32)
        self.r = rig.row_slopes().astype(np.float32)
        self.g0 = int(np.count_nonzero(self.r <= 1e-6))  # rows above (or on) the horizon
        z = np.minimum(rig.camera_height / np.maximum(self.r[self.g0:], 1e-6), MAX_GROUND_M).astype(np.float32)
        self.ground_z = z
        az = np.radians(90.0 - c.sun_azimuth_deg)
        el = np.radians(c.sun_elevation_deg)
        self.sun_dir = np.array([np.cos(az), np.sin(az)]) * np.cos(el)
        self.ambient = np.asarray(c.ambient, np.float32)
        self.sun = np.asarray(c.sun, np.float32)
        self.fog = np.asarray(c.fog_color, np.float32)
        # Ground: out = surface (0..255) * grain * A + B, all of lighting, detail fade, wetness and fog folded in.
        light = (self.ambient + self.sun * np.float32(max(np.sin(el), 0.0)))[None, None, :]
        if c.headlights:
            lateral = np.exp(-(self.k / 0.4) ** 2)
            reach = np.clip(15.0 / z, 0.0, 1.0) ** 2 * np.clip((z - 1.5) / 2.0, 0.0, 1.0)
            light = light + (c.headlights * reach[:, None] * lateral[None, :])[..., None]
            self.head_lateral = np.exp(-(self.k / 0.5) ** 2).astype(np.float32)
        detail = np.clip((DETAIL_FAR_M - z) / (DETAIL_FAR_M - DETAIL_NEAR_M), 0.0, 1.0)[:, None, None]
        fog_t = np.exp(-z / c.fog_m)[:, None, None]
        wet = 1.0 - 0.4 * c.wet
        self.ground_a = (detail * wet * light * fog_t).astype(np.float32)
        base = _GROUND_MEAN * (1.0 - detail) * wet + 0.2 * c.wet * np.asarray(c.sky_horizon)
        self.ground_b = (255.0 * (base * light * fog_t + self.fog * (1.0 - fog_t))).astype(np.float32)
        elevation = np.degrees(np.arctan(-self.r[: self.g0].astype(float)))
        sun = (90.0 - c.sun_azimuth_deg, c.sun_elevation_deg, c.sun_glow, 12.0) if c.sun_glow else None
        self.sky = 255.0 * sky_panorama(self.g0, elevation, c.sky_zenith, c.sky_horizon, c.clouds, c.cloud_color,
                                        sun, self.seed)
        self.sky_rows = np.broadcast_to(np.arange(self.g0, dtype=np.float32)[:, None], (self.g0, rig.width)).copy()
        # Colour: saturation about the luminance, then the tint, as one 3x3 matrix (None when it is the identity).
        luma = np.array([0.114, 0.587, 0.299])
        matrix = np.diag(c.tint) @ (c.saturation * np.eye(3) + (1.0 - c.saturation) * np.outer(np.ones(3), luma))
        self.color_matrix = None if np.allclose(matrix, np.eye(3)) else matrix.astype(np.float32)
        rng = np.random.default_rng([self.seed, 9])
        self.noise = (rng.standard_normal((NOISE_BANK, rig.height, rig.width)) * c.noise_std).astype(np.float32)
        x = np.arange(256) / 255.0
        self.lut = np.clip(255.0 * (0.5 + c.contrast * (x ** (1.0 / c.gamma) - 0.5)), 0, 255).astype(np.uint8)

    def _walls(self, cam: NDArray[np.float64], yaw: float, background: NDArray[np.float32]) -> None:
        """Draw the walls over ``background`` (H, W, 3), in place: lit, fogged, faded out near the view distance."""
        rig, walls, c = self.rig, self.scene.walls, self.cond
        if not len(walls):
            return
        hits = cast(walls, walls.near(cam, self.view), cam, yaw, self.k)
        has = (hits.piece >= 0) & (hits.depth < self.view)
        if not has.any():
            return
        piece = np.where(has, hits.piece, 0)
        depth = np.where(has, hits.depth, np.float32(0.0))
        height = np.where(has, walls.height[piece], np.float32(-1.0))
        hgt = np.float32(rig.camera_height) - self.r[:, None] * depth[None, :]
        mask = (hgt >= 0) & (hgt <= height[None, :])
        ty0, tx0 = Scene.tile_origin(walls.tile[piece])
        u = (np.mod((walls.u0[piece] + hits.along) / TEXEL_M, TILE_W) + tx0).astype(np.float32)
        tex_h = hgt
        if height.max() > TILE_H * TEXEL_M - 0.5:  # taller than a tile: repeat the upper floors
            tex_h = np.where(hgt > 24.0, 8.0 + np.mod(hgt - 8.0, 16.0), hgt)
        map_y = np.clip(tex_h, 0.0, (TILE_H - 1) * TEXEL_M) * np.float32(-1 / TEXEL_M) \
            + (ty0 + TILE_H - 1).astype(np.float32)[None, :]
        map_x = np.broadcast_to(u[None, :], map_y.shape)
        sample = cv2.remap(self.scene.atlas, map_x, map_y, cv2.INTER_LINEAR)
        # Per column: ambient + sun on the facade normal, fog transmittance, fade-out near the view distance.
        lambert = np.maximum(walls.normal[piece] @ self.sun_dir, 0.0).astype(np.float32)
        light = self.ambient[None, :] + lambert[:, None] * self.sun[None, :]
        fade = np.clip((self.view - depth) / (0.25 * self.view), 0.0, 1.0).astype(np.float32)
        fog_t = np.exp(-depth / c.fog_m).astype(np.float32)
        gain = (light * (fog_t * fade)[:, None])[None]
        wall = sample * gain + (255.0 * self.fog[None, :] * ((1.0 - fog_t) * fade)[:, None])[None]
        if c.headlights:
            near = np.clip(12.0 / np.maximum(depth, 1e-3), 0.0, 1.0) ** 2 * self.head_lateral * fog_t * fade
            wall += sample * (c.headlights * near[None, :] * np.exp(-np.maximum(hgt - 1.0, 0.0) / 2.0))[..., None]
        if c.window_glow:
            glow = cv2.remap(self.scene.glow, map_x, map_y, cv2.INTER_LINEAR).astype(np.float32)
            wall += (glow * (fog_t * fade * c.window_glow)[None, :])[..., None] * np.asarray(c.glow_color, np.float32)
        faded = np.flatnonzero(has & (fade < 1.0))
        if len(faded):  # cross-fade with the sky or ground behind
            wall[:, faded] += background[:, faded] * (1.0 - fade[faded])[None, :, None]
        np.copyto(background, wall, where=mask[..., None])

    def _ground(self, cam: NDArray[np.float64], yaw: float) -> NDArray[np.float32]:
        """Road surface of the rows below the horizon: inverse perspective mapping, grain, light and fog."""
        fwd = np.array([np.cos(yaw), np.sin(yaw)])
        right = np.array([fwd[1], -fwd[0]])
        ax = (fwd[0] + self.k * right[0]).astype(np.float32)
        ay = (fwd[1] + self.k * right[1]).astype(np.float32)
        dx = self.ground_z[:, None] * ax[None, :]
        dy = self.ground_z[:, None] * ay[None, :]
        raster, x0, y1 = self.scene.ground(cam)
        mx = (dx + np.float32(cam[0] - x0)) * np.float32(1 / TEXEL_M)
        my = (np.float32(y1 - cam[1]) - dy) * np.float32(1 / TEXEL_M)
        surface = cv2.remap(raster, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=PAVING)
        period = np.float32(GRAIN_SIZE * GRAIN_TEXEL_M)
        gx = np.mod(dx + np.float32(cam[0] % period), period) * np.float32(1 / GRAIN_TEXEL_M)
        gy = np.mod(np.float32(-cam[1] % period) - dy, period) * np.float32(1 / GRAIN_TEXEL_M)
        grain = cv2.remap(self.scene.grain, gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        ground = np.multiply(surface, grain[..., None], dtype=np.float32)
        ground *= self.ground_a
        ground += self.ground_b
        return ground

    def _sky(self, yaw: float) -> NDArray[np.float32]:
        """Sky rows above the horizon: the panorama at each column's azimuth."""
        azimuth = yaw - np.arctan(self.k.astype(float))
        px = np.mod(azimuth / (2 * np.pi) * SKY_WIDTH, SKY_WIDTH).astype(np.float32)
        map_x = np.broadcast_to(px[None, :], self.sky_rows.shape)
        return cv2.remap(self.sky, map_x, self.sky_rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)

    def render(self, xy: NDArray[np.float64], yaw: float, frame: int = 0, camera: int = 0) -> NDArray[np.uint8]:
        """BGR image (H, W, 3) of a camera at map ``xy`` with optical axis ``yaw`` (radians from east)."""
        rig, c = self.rig, self.cond
        cam = np.asarray(xy, float)
        out = np.empty((rig.height, rig.width, 3), np.float32)
        if self.g0:
            out[: self.g0] = self._sky(float(yaw))
        if self.g0 < rig.height:
            out[self.g0:] = self._ground(cam, float(yaw))
        self._walls(cam, float(yaw), out)
        if self.color_matrix is not None:
            out = cv2.transform(out, self.color_matrix)
        rng = np.random.default_rng([self.seed, 10, int(frame), int(camera)])
        if c.rain:
            out = self._rain(out, rng)
        if c.blur_px:
            out = cv2.GaussianBlur(out, (0, 0), c.blur_px * rig.width / 620.0)
        out += self.noise[int(rng.integers(NOISE_BANK))][..., None]
        np.clip(out, 0.0, 255.0, out=out)
        return cv2.LUT(out.astype(np.uint8), self.lut)

    def _rain(self, out: NDArray[np.float32], rng: np.random.Generator) -> NDArray[np.float32]:
        """Seeded bright, slanted, slightly blurred streaks."""
        h, w = out.shape[:2]
        layer = np.zeros((h, w), np.float32)
        scale = h / 376.0
        n = self.cond.rain
        x = rng.uniform(0, w, n)
        y = rng.uniform(-20 * scale, h, n)
        length = rng.uniform(8, 25, n) * scale
        slant = rng.normal(0.15, 0.05, n)
        alpha = rng.uniform(0.15, 0.45, n)
        for xi, yi, li, si, ai in zip(x, y, length, slant, alpha):
            cv2.line(layer, (int(xi), int(yi)), (int(xi + si * li), int(yi + li)), float(ai), 1, cv2.LINE_AA)
        layer = cv2.GaussianBlur(layer, (0, 0), 0.6)[..., None]
        return out * (1.0 - layer) + np.float32(0.85 * 255.0) * layer

    def right_camera(self, xy: NDArray[np.float64], yaw: float) -> NDArray[np.float64]:
        """Map position of the right camera of the rig whose left camera is at ``xy``."""
        return np.asarray(xy, float) + self.rig.baseline * np.array([np.sin(yaw), -np.cos(yaw)])

    def stereo_pair(self, xy: NDArray[np.float64], yaw: float, frame: int = 0) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
        """Left and right BGR images of the rig whose left camera is at ``xy`` (optical axis ``yaw``)."""
        return self.render(xy, yaw, frame, 0), self.render(self.right_camera(xy, yaw), yaw, frame, 1)
