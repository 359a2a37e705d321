"""The controller's camera: the place images' camera (``place.image``) with rows added below until it sees the ground
``drive.camera.nearest_ground_m`` ahead, and columns added on both sides until it sees ``drive.camera.hfov_deg`` across
(:func:`drive_rig`). The place images' camera sees the road from 6.5 m on (at 160 x 48), farther than the expert's aim
point (4-5 m), and 82 deg across, less than a junction turn sweeps; the localization reads the place image's window of
each image (:func:`place_window`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from topoloc.errors import InputError
from topoloc.place.images import make_rig
from topoloc.render.rig import StereoRig


def drive_rig(conf: dict[str, Any]) -> StereoRig:
    """The controller's camera: the place images' (``place.image``) with as many rows added below as it takes for the
    bottom row to see the ground ``drive.camera.nearest_ground_m`` ahead (none when that is null or already seen), and
    as many columns added on each side as it takes to see ``drive.camera.hfov_deg`` across (none when null)."""
    rig = make_rig(conf["place"]["image"], conf["render"])
    camera = conf["drive"]["camera"]
    near, hfov = camera["nearest_ground_m"], camera.get("hfov_deg")
    if near is not None:
        rows = int(np.ceil(rig.cy + rig.camera_height * rig.f / float(near))) + 1  # row v sees the ground at h f / (v - cy)
        rig = dataclasses.replace(rig, height=max(rig.height, rows))
    if hfov is not None:
        side = side_columns(rig, float(hfov))
        rig = dataclasses.replace(rig, width=rig.width + 2 * side, cx=rig.cx + side)
    return rig


def hfov_deg(rig: StereoRig) -> float:
    """The horizontal field of view of ``rig`` in degrees, from the outer edges of its first and last columns."""
    return float(np.degrees(np.arctan((rig.cx + 0.5) / rig.f) + np.arctan((rig.width - 0.5 - rig.cx) / rig.f)))


def side_columns(rig: StereoRig, hfov: float) -> int:
    """The fewest columns to add on each side of ``rig`` for it to see at least ``hfov`` degrees across."""
    if not 0.0 < hfov < 180.0:
        raise InputError("drive.camera.hfov_deg", f"a horizontal field of view between 0 and 180 degrees, got {hfov}")
    side = max(0, int(np.floor(rig.f * np.tan(np.radians(hfov) / 2.0) - rig.width / 2.0)))
    while hfov_deg(dataclasses.replace(rig, width=rig.width + 2 * side, cx=rig.cx + side)) < hfov:
        side += 1
    return side


def place_window(conf: dict[str, Any]) -> tuple[slice, slice]:
    """The rows and columns of the controller's image (:func:`drive_rig`) that are the place images' camera: its top
    ``place.image.height`` rows, and the ``place.image.width`` columns between the ones added on each side."""
    image = conf["place"]["image"]
    side = (drive_rig(conf).width - int(image["width"])) // 2
    return slice(0, int(image["height"])), slice(side, side + int(image["width"]))


def image_shape(conf: dict[str, Any]) -> tuple[int, int, int]:
    """(H, W, C) of the controller's images (:func:`drive_rig`, ``place.image.color``)."""
    rig = drive_rig(conf)
    return rig.height, rig.width, 3 if conf["place"]["image"]["color"] else 1
