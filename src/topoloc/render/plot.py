"""The contact sheet: sample frames of a route, one row per appearance condition."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from topoloc.io import atomic_path

LABEL_W = 150


def contact_sheet(rows: dict[str, list[NDArray[np.uint8]]], frames: list[int], path: str | Path, title: str,
                  highlight: str | None = None) -> None:
    """Write a grid of BGR images (one row per condition name, one column per frame index) as a PNG."""
    names = list(rows)
    h, w = rows[names[0]][0].shape[:2]
    header = 50
    sheet = np.full((header + len(names) * (h + 4), LABEL_W + len(frames) * (w + 4), 3), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(sheet, title, (8, 22), font, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    for j, frame in enumerate(frames):
        cv2.putText(sheet, f"frame {frame}", (LABEL_W + j * (w + 4) + 4, header - 6), font, 0.45, (60, 60, 60), 1,
                    cv2.LINE_AA)
    for i, name in enumerate(names):
        y = header + i * (h + 4)
        color = (0, 0, 200) if name == highlight else (0, 0, 0)
        cv2.putText(sheet, name, (8, y + h // 2 + 5), font, 0.55, color, 2 if name == highlight else 1, cv2.LINE_AA)
        for j, image in enumerate(rows[name]):
            x = LABEL_W + j * (w + 4)
            sheet[y:y + h, x:x + w] = image if image.ndim == 3 else image[..., None]
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), sheet):
            raise OSError(f"cannot write {path}")
