"""Place images: poses rendered under several appearance conditions at the network's input size.

Three sets are rendered (stage ``render_places``), all in the street scenes of :mod:`topoloc.render`:

* **route**: the evaluation route is render route ``place.route`` (the path of drive ``ren<RR>_*``,
  :func:`topoloc.render.drives.drive_path`). The *teach* drive is that path, one image per frame,
  under ``place.teach_condition``. The *repeat* drive follows the same route with other frames: every
  ``repeat.frame_spacing_m`` from ``repeat.phase_m``, weaving ``repeat.lateral_m`` about the teach path
  (period ``repeat.weave_period_m``) with a smooth heading jitter of ``repeat.yaw_deg``; it is rendered
  under every condition of ``place.repeat_conditions`` (one trajectory, several appearances).
* **train**: ``train.routes`` other random routes (seeded by ``place.seed``), of which the last
  ``train.val_routes`` are for validation. Frames closer than ``train.min_distance_m`` to the evaluation
  route are dropped, so training and evaluation places are disjoint; the set is rendered under every
  condition (training uses ``train.conditions`` only; the others are reported as held out).

A :class:`PlaceSet` holds images of shape (conditions, places, H, W, channels), BGR or grey, uint8, with
the ground-truth pose of each place. Rendering at the input size (160 x 48 by default) is far cheaper
than rendering KITTI-size images and shrinking them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree
from tqdm import tqdm

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path
from topoloc.motion.route import CameraPath, render_route
from topoloc.render.conditions import get_condition
from topoloc.render.drives import drive_path, drive_scene
from topoloc.render.renderer import Renderer
from topoloc.render.rig import KITTI_BASELINE_M, StereoRig


@dataclass
class PlaceSet:
    """Images ``(conditions, places, H, W, C)`` uint8 and the ground truth of each place.

    ``xy`` (places, 2) map position (graph CRS), ``yaw`` heading (radians from east), ``route`` route index,
    ``frame`` frame index in its route, ``edge`` the road edge of the route at that frame (-1: unknown).
    """

    images: NDArray[np.uint8]
    conditions: list[str]
    xy: NDArray[np.float64]
    yaw: NDArray[np.float64]
    route: NDArray[np.int64]
    frame: NDArray[np.int64]
    edge: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        if self.edge is None:
            self.edge = np.full(len(self.xy), -1, np.int64)

    def __len__(self) -> int:
        return len(self.xy)

    def condition(self, name: str) -> NDArray[np.uint8]:
        """The images ``(places, H, W, C)`` of condition ``name``."""
        if name not in self.conditions:
            raise InputError("place", f"condition {name!r} was not rendered (have {self.conditions})")
        return self.images[self.conditions.index(name)]

    def subset(self, mask: NDArray[np.bool_]) -> PlaceSet:
        """The places where ``mask`` is true."""
        return PlaceSet(self.images[:, mask], list(self.conditions), self.xy[mask], self.yaw[mask], self.route[mask],
                        self.frame[mask], self.edge[mask])

    def save(self, path: str | Path) -> None:
        """Write as an uncompressed ``.npz`` (rendered noise does not compress), atomically."""
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as handle:
                np.savez(handle, images=self.images, conditions=np.array(self.conditions), xy=self.xy, yaw=self.yaw,
                         route=self.route, frame=self.frame, edge=self.edge)

    @classmethod
    def load(cls, path: str | Path) -> PlaceSet:
        """Read a set written by :meth:`save`; InputError naming the file otherwise."""
        try:
            with np.load(path) as data:
                return cls(data["images"], [str(c) for c in data["conditions"]], data["xy"], data["yaw"],
                           data["route"].astype(np.int64), data["frame"].astype(np.int64),
                           data["edge"].astype(np.int64) if "edge" in data.files else None)
        except (OSError, KeyError, ValueError) as err:
            raise InputError(path, f"not a place image set ({err})") from err


def make_rig(image: dict[str, Any], render_conf: dict[str, Any]) -> StereoRig:
    """The camera of the place images: KITTI intrinsics scaled to ``place.image`` width x height, mounted at
    ``render.camera_height_m`` (the left camera only: the baseline plays no part)."""
    return StereoRig.kitti(int(image["width"]), int(image["height"]), KITTI_BASELINE_M,
                           float(render_conf["camera_height_m"]), where="place.image")


def render_images(renderer: Renderer, xy: NDArray[np.float64], yaw: NDArray[np.float64], color: bool,
                  desc: str = "render") -> NDArray[np.uint8]:
    """Left-camera images ``(n, H, W, C)`` at the given poses (C = 3 BGR, or 1 grey)."""
    rig = renderer.rig
    out = np.empty((len(xy), rig.height, rig.width, 3 if color else 1), np.uint8)
    for k in tqdm(range(len(xy)), desc=desc, unit="image", mininterval=5.0):
        image = renderer.render(xy[k], float(yaw[k]), k)
        out[k] = image if color else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)[..., None]
    return out


def render_conditions(scene: Any, rig: StereoRig, conditions: list[str], xy: NDArray[np.float64],
                      yaw: NDArray[np.float64], seed: int, view_m: float, color: bool) -> NDArray[np.uint8]:
    """Images ``(conditions, n, H, W, C)`` of the poses under each condition (one renderer per condition)."""
    return np.stack([render_images(Renderer(scene, rig, get_condition(name), seed, view_m), xy, yaw, color, name)
                     for name in conditions])


def route_path(graph: RoadGraph, render_conf: dict[str, Any], route: int) -> CameraPath:
    """The evaluation route: the camera path of render route ``route`` (as drive ``ren<route>_*``)."""
    return drive_path(graph, render_conf, int(route))


def repeat_poses(path: CameraPath, repeat: dict[str, Any], seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Poses of the repeat drive along ``path`` (see the module docstring)."""
    spacing, phase = float(repeat["frame_spacing_m"]), float(repeat["phase_m"])
    if spacing <= 0:
        raise InputError("place.repeat.frame_spacing_m", f"must be positive, got {spacing}")
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path.xy, axis=0).T))])
    s = np.arange(phase, cum[-1], spacing)
    if len(s) < 2:
        raise InputError("place.repeat.phase_m", f"leaves fewer than two repeat frames on a {cum[-1]:.0f} m route")
    yaw_path = np.unwrap(path.yaw)
    x, y = np.interp(s, cum, path.xy[:, 0]), np.interp(s, cum, path.xy[:, 1])
    yaw = np.interp(s, cum, yaw_path)
    lateral = float(repeat["lateral_m"]) * np.sin(2 * np.pi * s / float(repeat["weave_period_m"]))
    xy = np.column_stack([x + lateral * np.sin(yaw), y - lateral * np.cos(yaw)])  # + to the right of travel
    rng = np.random.default_rng([int(seed), 11])
    jitter = gaussian_filter1d(rng.standard_normal(len(s)), 5.0)
    jitter *= np.radians(float(repeat["yaw_deg"])) / max(float(np.std(jitter)), 1e-9)
    return xy, yaw + jitter


def polyline_distance(points: NDArray[np.float64], line: NDArray[np.float64], step_m: float = 1.0) -> NDArray[np.float64]:
    """Distance of each point to the polyline ``line`` (densified every ``step_m``)."""
    seg = np.diff(line, axis=0)
    dense = [line[:1]]
    for a, d in zip(line[:-1], seg):
        n = max(1, int(np.ceil(np.hypot(*d) / step_m)))
        dense.append(a + d * (np.arange(1, n + 1) / n)[:, None])
    dist, _ = cKDTree(np.concatenate(dense)).query(points)
    return np.asarray(dist, float)


def training_paths(graph: RoadGraph, render_conf: dict[str, Any], train: dict[str, Any], seed: int,
                   avoid_xy: NDArray[np.float64]) -> list[tuple[CameraPath, NDArray[np.bool_]]]:
    """``train.routes`` random camera paths and, per path, the frames at least ``min_distance_m`` from ``avoid_xy``.

    A route with fewer than ``min_frames`` frames left is replaced by another draw (up to 20 per route).
    """
    out = []
    min_distance, min_frames = float(train["min_distance_m"]), int(train["min_frames"])
    for i in range(int(train["routes"])):
        best = None
        for attempt in range(20):
            rng = np.random.default_rng([int(seed), 7919, i, attempt])
            path = render_route(graph, float(train["route_length_m"]), float(render_conf["frame_spacing_m"]), rng,
                                float(render_conf["smoothing_m"]), float(render_conf["lane_offset_m"]),
                                float(render_conf["max_turn_deg"]))
            keep = polyline_distance(path.xy, avoid_xy) >= min_distance
            if best is None or keep.sum() > best[1].sum():
                best = (path, keep)
            if keep.sum() >= min_frames:
                break
        if best is None or best[1].sum() < min_frames:
            raise InputError("place.train.min_distance_m", f"training route {i}: no route keeps {min_frames} frames "
                             f"{min_distance} m away from the evaluation route on this map")
        out.append(best)
    return out


def render_training_set(osm: str | None, graph: RoadGraph, render_conf: dict[str, Any], place: dict[str, Any],
                        avoid_xy: NDArray[np.float64], conditions: list[str]) -> PlaceSet:
    """The training and validation places (every kept frame of every training route) under ``conditions``."""
    rig = make_rig(place["image"], render_conf)
    color, view = bool(place["image"]["color"]), float(render_conf["view_distance_m"])
    sets = []
    for i, (path, keep) in enumerate(training_paths(graph, render_conf, place["train"], int(place["seed"]), avoid_xy)):
        scene = drive_scene(osm, graph, path, render_conf)
        xy, yaw = path.xy[keep], path.yaw[keep]
        seed = int(np.random.SeedSequence([int(place["seed"]), 7919, i]).generate_state(1)[0])
        images = render_conditions(scene, rig, conditions, xy, yaw, seed, view, color)
        sets.append(PlaceSet(images, conditions, xy, yaw, np.full(len(xy), i), np.flatnonzero(keep), path.edge_id[keep]))
    return concat(sets)


def concat(sets: list[PlaceSet]) -> PlaceSet:
    """Places of several sets with the same conditions, one after the other."""
    return PlaceSet(np.concatenate([s.images for s in sets], axis=1), list(sets[0].conditions),
                    np.concatenate([s.xy for s in sets]), np.concatenate([s.yaw for s in sets]),
                    np.concatenate([s.route for s in sets]), np.concatenate([s.frame for s in sets]),
                    np.concatenate([s.edge for s in sets]))
