"""A repeat drive a person can watch: an animated GIF of its :class:`~topoloc.drive.episodes.MovieFrame` s, each the
camera view beside the map (the route's lane in grey, the path driven so far in blue, the vehicle as a red arrow,
the vertex it is localized at as a green dot), under a line with the time, the command, the steering and the speed."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw

from topoloc.drive.episodes import MovieFrame
from topoloc.errors import InputError
from topoloc.io import atomic_path

_TEXT_PX = 14  # height of the caption line


def _to_rgb(image: NDArray[np.uint8]) -> Image.Image:
    """The simulator's image (BGR, or one channel) as an RGB image."""
    array = np.asarray(image)
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    elif array.ndim == 3:
        array = np.ascontiguousarray(array[:, :, ::-1])
    return Image.fromarray(array.astype(np.uint8)).convert("RGB")


class _MapView:
    """Map metres to the pixels of a square panel that holds the whole lane."""

    def __init__(self, lane: NDArray[np.float64], size: int) -> None:
        lo, hi = lane.min(axis=0), lane.max(axis=0)
        self.centre, self.size = (lo + hi) / 2, size
        self.scale = 0.9 * size / max(float((hi - lo).max()), 1.0)

    def __call__(self, xy: NDArray[np.float64]) -> list[tuple[float, float]]:
        p = (np.atleast_2d(xy) - self.centre) * self.scale
        return [(float(self.size / 2 + x), float(self.size / 2 - y)) for x, y in p]


def movie_frames(frames: Sequence[MovieFrame], lane: NDArray[np.float64], vertex_xy: NDArray[np.float64], title: str,
                 height_px: int) -> list[Image.Image]:
    """The images of a drive's movie (see the module docstring); ``vertex_xy``: the true position of each map vertex."""
    if not frames:
        raise InputError("drive.follow.movie", f"{title}: the drive recorded no movie frame")
    view = _MapView(lane, height_px)
    base = Image.new("RGB", (height_px, height_px), (250, 250, 250))
    ImageDraw.Draw(base).line(view(lane[::4]), fill=(170, 170, 170), width=max(3, height_px // 60))
    driven: list[tuple[float, float]] = []
    out = []
    for f in frames:
        camera = _to_rgb(f.image)
        camera = camera.resize((max(1, round(camera.width * height_px / camera.height)), height_px), Image.BILINEAR)
        panel = base.copy()
        draw = ImageDraw.Draw(panel)
        driven += view(f.xy)
        if len(driven) > 1:
            draw.line(driven, fill=(40, 90, 200), width=2)
        (lx, ly), = view(vertex_xy[f.vertex])
        draw.ellipse((lx - 4, ly - 4, lx + 4, ly + 4), fill=(30, 160, 60))
        (x, y), = view(f.xy)
        tip = (x + 10 * np.cos(f.yaw), y - 10 * np.sin(f.yaw))
        left = (x + 5 * np.cos(f.yaw + 2.5), y - 5 * np.sin(f.yaw + 2.5))
        right = (x + 5 * np.cos(f.yaw - 2.5), y - 5 * np.sin(f.yaw - 2.5))
        draw.polygon([tip, left, right], fill=(210, 30, 30))
        frame = Image.new("RGB", (camera.width + height_px, height_px + _TEXT_PX), (255, 255, 255))
        frame.paste(camera, (0, _TEXT_PX))
        frame.paste(panel, (camera.width, _TEXT_PX))
        ImageDraw.Draw(frame).text((3, 1), f"{title}  t={f.t:4.1f}s  {f.command:<8}  steer {f.steer:+.2f}  "
                                            f"{f.speed:4.1f} m/s", fill=(0, 0, 0))
        out.append(frame)
    return out


def write_movie(frames: Sequence[MovieFrame], lane: NDArray[np.float64], vertex_xy: NDArray[np.float64], title: str,
                path: str, height_px: int = 180, fps: int = 10) -> int:
    """Write the drive's movie as an animated GIF at ``path`` (atomically); return its size in bytes."""
    images = [im.quantize(colors=64, method=Image.Quantize.MEDIANCUT)
              for im in movie_frames(frames, lane, vertex_xy, title, height_px)]
    with atomic_path(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=round(1000 / fps), loop=0,
                       optimize=True)
        size = tmp.stat().st_size
    return int(size)
