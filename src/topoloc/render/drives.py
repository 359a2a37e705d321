"""Rendered drives as a library: the rig, camera path, scene, seeds and poses of drive ``ren<RR>_<condition>``.

Shared by the ``render_drive`` stage (which writes a drive as a KITTI sequence) and the place images
(which render the same routes at the network's input size). Drive names are checked in
:mod:`topoloc.render.conditions`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.georef import Georeference
from topoloc.motion.poses import poses_from_planar
from topoloc.motion.route import CameraPath, render_route
from topoloc.render.rig import StereoRig
from topoloc.render.scene import Scene, scene_for_path


def make_rig(conf: dict[str, Any]) -> StereoRig:
    """The stereo rig of a ``render`` config slice."""
    return StereoRig.kitti(int(conf["width"]), int(conf["height"]), float(conf["baseline_m"]), float(conf["camera_height_m"]))


def drive_path(graph: RoadGraph, conf: dict[str, Any], route: int) -> CameraPath:
    """The camera path of route ``route`` (seeded by ``render.seed`` and the route index)."""
    if float(conf["length_m"]) < 2 * float(conf["frame_spacing_m"]):
        raise InputError("render.length_m", f"{conf['length_m']} m is shorter than two frames")
    rng = np.random.default_rng([int(conf["seed"]), route])
    return render_route(graph, float(conf["length_m"]), float(conf["frame_spacing_m"]), rng,
                        float(conf["smoothing_m"]), float(conf["lane_offset_m"]), float(conf["max_turn_deg"]))


def drive_scene(osm: str | None, graph: RoadGraph, path: CameraPath, conf: dict[str, Any]) -> Scene:
    """The scene around a camera path, from the ``render.buildings`` settings."""
    scene_conf = {**conf["buildings"], "view_distance_m": float(conf["view_distance_m"])}
    return scene_for_path(osm, graph, path.xy, scene_conf, int(conf["seed"]))


def route_seed(conf: dict[str, Any], route: int) -> int:
    """Seed of the per-image noise and rain of a route."""
    return int(np.random.SeedSequence([int(conf["seed"]), route]).generate_state(1)[0])


def local_poses(xy: NDArray[np.float64], yaw: NDArray[np.float64]) -> tuple[NDArray[np.float64], Georeference]:
    """KITTI poses with frame 0 at the origin looking along +z, and the georeference back to the map."""
    geo = Georeference(float(yaw[0] - np.pi / 2.0), np.asarray(xy[0], float).copy())
    local = (xy - geo.t) @ geo.rotation
    return poses_from_planar(local, yaw - geo.theta), geo


def sample_frames(n: int, count: int) -> list[int]:
    """``count`` frame indices spread evenly inside ``0..n-1``."""
    return sorted({int(round(v)) for v in np.linspace(0, n - 1, count + 2)[1:-1]}) or [0]
