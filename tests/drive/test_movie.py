"""The movie of a repeat drive: an animated GIF, one frame per movie frame, the camera view beside the map."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from topoloc.drive.episodes import MovieFrame
from topoloc.drive.movie import movie_frames, write_movie
from topoloc.errors import InputError


def _frames(n: int) -> tuple[list[MovieFrame], np.ndarray]:
    lane = np.stack([np.linspace(0.0, 100.0, 101), np.zeros(101)], axis=1)
    image = np.zeros((48, 64, 3), np.uint8)
    image[:, :, 0] = 255  # blue in the simulator's BGR
    frames = [MovieFrame(image, lane[10 * k], 0.0, 10 * k, "left" if k % 2 else "follow", 0.1, 5.0, k * 0.5)
              for k in range(n)]
    return frames, lane


def test_the_movie_shows_the_camera_beside_the_map_with_the_vehicle(tmp_path):
    frames, lane = _frames(6)
    images = movie_frames(frames, lane, lane, "Topo-LP (ground truth)", 120)
    assert len(images) == 6 and images[0].size == (160 + 120, 120 + 14)
    first = np.asarray(images[0])
    assert tuple(first[60, 40]) == (0, 0, 255)  # the camera view, BGR turned to RGB
    panel = first[14:, 160:]
    red = (panel[:, :, 0] > 180) & (panel[:, :, 1] < 80) & (panel[:, :, 2] < 80)
    cols = [np.flatnonzero(red.any(axis=0)).mean() for panel in (np.asarray(im)[14:, 160:] for im in images[:2])
            for red in [(panel[:, :, 0] > 180) & (panel[:, :, 1] < 80) & (panel[:, :, 2] < 80)]]
    assert red.any() and cols[1] > cols[0] + 5  # the vehicle moves east on the map
    path = tmp_path / "drive.gif"
    size = write_movie(frames, lane, lane, "Topo-LP (ground truth)", str(path), 120, 5)
    gif = Image.open(path)
    assert size == path.stat().st_size and gif.n_frames == 6 and gif.size == (280, 134)
    with pytest.raises(InputError, match="drive.follow.movie"):
        movie_frames([], lane, lane, "x", 120)
