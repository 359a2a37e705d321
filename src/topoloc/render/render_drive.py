"""Stage ``render_drive``: a rendered stereo drive on the region's map, written as a KITTI sequence.

Drive ``ren<RR>_<condition>`` is route ``RR`` (a smooth random route on the road graph, seeded by
``render.seed`` and ``RR``, see :mod:`topoloc.motion.route`) seen under ``condition``: all conditions of
one route share the path, the buildings and their textures, so the same places look different only by
their appearance. Outputs, beside each other in ``results/{region}/render/{drive}/``:

* ``image_0/``, ``image_1/``: left and right grey images ``000000.png``, ... (KITTI layout);
* ``calib.txt`` (P0..P3, Tr), ``poses.txt`` (ground truth of the left camera, KITTI format, frame 0 at
  the origin looking along +z), ``times.txt`` (seconds, at ``render.speed_mps``);
* ``gps.csv`` (``frame,lat,lon``: the exact WGS84 position of each frame, so ``extract_odometry``
  georeferences the drive exactly as a KITTI drive with RTK GPS), ``route.csv`` (map position, heading
  and true road edge of each frame);
* ``render.json`` (rig, condition, scene and timing facts) and ``contact_sheet.png`` (sample frames of
  the route under every condition in ``render.sheet.conditions``).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
import pyproj
from tqdm import tqdm

from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, publish_dir, temporary_dir, write_json, write_text
from topoloc.motion.poses import write_poses
from topoloc.motion.route import CameraPath
from topoloc.render.conditions import get_condition, parse_drive
from topoloc.render.drives import (
    drive_path,
    drive_scene,
    local_poses,
    make_rig,
    route_seed,
    sample_frames,
)
from topoloc.render.plot import contact_sheet
from topoloc.render.renderer import Renderer

log = logging.getLogger(__name__)

# Fast PNG: the sensor noise leaves little for LZ77 to find; Huffman coding alone is faster and smaller.
PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]


def _write_images(renderer: Renderer, path: CameraPath, left_dir: Path, right_dir: Path) -> dict[str, float]:
    """Render every stereo pair into fresh ``left_dir`` / ``right_dir`` (atomically: a temporary folder, then renamed)."""
    render_s = render_cpu_s = 0.0
    started = time.perf_counter()
    with temporary_dir(left_dir) as tmp:  # .topoloc-tmp.image_0.*: removed by a rerun if this job is killed
        (tmp / "image_0").mkdir()
        (tmp / "image_1").mkdir()
        for k in tqdm(range(len(path.xy)), desc="render", unit="pair", mininterval=2.0):
            t0, c0 = time.perf_counter(), time.process_time()
            left, right = renderer.stereo_pair(path.xy[k], float(path.yaw[k]), k)
            left, right = cv2.cvtColor(left, cv2.COLOR_BGR2GRAY), cv2.cvtColor(right, cv2.COLOR_BGR2GRAY)
            render_s += time.perf_counter() - t0
            render_cpu_s += time.process_time() - c0
            for folder, image in (("image_0", left), ("image_1", right)):
                if not cv2.imwrite(str(tmp / folder / f"{k:06d}.png"), image, PNG_PARAMS):
                    raise OSError(f"cannot write image {k} to {tmp / folder}")
        for name, dst in (("image_0", left_dir), ("image_1", right_dir)):
            publish_dir(tmp / name, dst)
    total = time.perf_counter() - started
    n = len(path.xy)
    return {"render_s": render_s, "render_pairs_per_s": n / render_s, "render_pairs_per_cpu_s": n / render_cpu_s,
            "render_and_write_s": total, "pairs_per_s_with_png": n / total}


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Render drive ``conf['drive']`` on ``inputs['graph']`` with the buildings of ``inputs['osm']`` (if given)."""
    drive = conf["drive"]
    route, condition_name = parse_drive(drive)
    for i, name in enumerate(conf["sheet"]["conditions"]):
        get_condition(name, f"render.sheet.conditions.{i}")
    condition = get_condition(condition_name, "drive")
    rig = make_rig(conf)
    graph = RoadGraph.load(inputs["graph"])
    started = time.perf_counter()
    path = drive_path(graph, conf, route)
    scene = drive_scene(inputs.get("osm"), graph, path, conf)
    scene_s = time.perf_counter() - started
    log.info("drive %s: %d frames, %.0f m, scene %s built in %.1f s", drive, len(path.xy), path.length_m, scene.facts(), scene_s)
    seed = route_seed(conf, route)
    renderer = Renderer(scene, rig, condition, seed, float(conf["view_distance_m"]))
    timing = _write_images(renderer, path, Path(outputs["left"]), Path(outputs["right"]))
    log.info("rendered %d pairs at %dx%d: %.1f pairs/s (%.1f per CPU second), %.1f pairs/s with PNG writing",
             len(path.xy), rig.width, rig.height, timing["render_pairs_per_s"], timing["render_pairs_per_cpu_s"],
             timing["pairs_per_s_with_png"])

    poses, geo = local_poses(path.xy, path.yaw)
    write_text(outputs["calib"], rig.calib_text())
    write_poses(outputs["poses"], poses)
    spacing, speed = float(conf["frame_spacing_m"]), float(conf["speed_mps"])
    write_text(outputs["times"], "".join(f"{k * spacing / speed:.6e}\n" for k in range(len(poses))))
    lon, lat = pyproj.Transformer.from_crs(graph.crs, "EPSG:4326", always_xy=True).transform(path.xy[:, 0], path.xy[:, 1])
    with atomic_path(outputs["gps"]) as tmp:
        pd.DataFrame({"frame": np.arange(len(poses)), "lat": lat, "lon": lon}).to_csv(tmp, index=False, float_format="%.9f")
    with atomic_path(outputs["route"]) as tmp:
        pd.DataFrame({"frame": np.arange(len(poses)), "x": path.xy[:, 0], "y": path.xy[:, 1],
                      "yaw_deg": np.degrees(path.yaw), "edge_id": path.edge_id}).to_csv(tmp, index=False, float_format="%.4f")

    frames = sample_frames(len(path.xy), int(conf["sheet"]["frames"]))
    rows = {}
    for name in conf["sheet"]["conditions"] or [condition_name]:
        other = renderer if name == condition_name else Renderer(scene, rig, get_condition(name), seed, float(conf["view_distance_m"]))
        rows[name] = [other.render(path.xy[k], float(path.yaw[k]), k) for k in frames]
    scale = min(1.0, 620.0 / rig.width)
    if scale < 1.0:
        rows = {n: [cv2.resize(im, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) for im in ims] for n, ims in rows.items()}
    contact_sheet(rows, frames, outputs["sheet"], f"{drive}: route {route}, {len(path.xy)} frames, {path.length_m:.0f} m "
                  f"(left camera; this drive: {condition_name})", highlight=condition_name)

    facts = {"frames": len(path.xy), "length_m": path.length_m, "scene_s": scene_s, **scene.facts(), **timing}
    stats = {"drive": drive, "route": route, "condition": condition.to_dict(), "crs": graph.crs,
             "rig": {"width": rig.width, "height": rig.height, "f": rig.f, "cx": rig.cx, "cy": rig.cy,
                     "baseline_m": rig.baseline, "camera_height_m": rig.camera_height},
             "route_edges": path.route, "distinct_edges": int(len(np.unique(path.edge_id))),
             "georeference": geo.to_dict(float(np.pi / 2.0)), "sheet_frames": frames, **facts}
    write_json(outputs["stats"], stats)
    return {k: float(v) for k, v in facts.items()}
