"""Stage ``render_places``: the place images of one split (``train``, ``teach`` or ``repeat``).

See :mod:`topoloc.place.images` for what each split holds. Outputs: ``places`` (a
:class:`~topoloc.place.images.PlaceSet` ``.npz``), ``stats`` (counts, distances, timing) and ``sheet``
(sample places, one row per condition). The images are rendered here, at the network's input size, rather
than read from ``render_drive``: that stage renders full-size grey stereo pairs of one condition per drive
for the visual odometry, while place recognition needs small colour images of many more places under
every condition (and training routes away from the evaluation route).
"""

from __future__ import annotations

import logging
import time
from typing import Any

import cv2
import numpy as np

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import write_json
from topoloc.place.images import (
    PlaceSet,
    make_rig,
    polyline_distance,
    render_conditions,
    render_training_set,
    repeat_poses,
    route_path,
)
from topoloc.render.conditions import CONDITIONS, check_conditions
from topoloc.render.drives import drive_scene, route_seed, sample_frames
from topoloc.render.plot import contact_sheet

log = logging.getLogger(__name__)

SPLITS = ("train", "teach", "repeat")


def _sheet(places: PlaceSet, path: str, title: str) -> None:
    frames = sample_frames(len(places), 4)
    rows = {name: [places.images[c, k] for k in frames] for c, name in enumerate(places.conditions)}
    scale = 2 if places.images.shape[2] < 100 else 1
    if scale > 1:
        rows = {n: [cv2.resize(im, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST) for im in ims]
                for n, ims in rows.items()}
    contact_sheet(rows, frames, path, title)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Render split ``conf['split']`` on ``inputs['graph']`` with the buildings of ``inputs['osm']``."""
    split, render_conf, place = conf["split"], conf["render"], conf["place"]
    if split not in SPLITS:
        raise InputError("split", f"{split!r} is not one of {SPLITS}")
    names = check_conditions(place)
    graph = RoadGraph.load(inputs["graph"])
    osm = inputs.get("osm")
    started = time.perf_counter()
    path = route_path(graph, render_conf, int(place["route"]))
    facts: dict[str, float] = {"route_length_m": path.length_m, "route_frames": float(len(path.xy))}
    if split == "train":
        conditions = list(CONDITIONS)  # all of them: training uses some, validation reports every one
        places = render_training_set(osm, graph, render_conf, place, path.xy, conditions)
        gap = polyline_distance(places.xy, path.xy)
        facts |= {"min_distance_to_route_m": float(gap.min()), "training_routes": float(len(np.unique(places.route)))}
    else:
        rig = make_rig(place["image"], render_conf)
        scene = drive_scene(osm, graph, path, render_conf)
        seed = route_seed(render_conf, int(place["route"]))
        color, view = bool(place["image"]["color"]), float(render_conf["view_distance_m"])
        if split == "teach":
            conditions, xy, yaw, edge = names["teach"], path.xy, path.yaw, path.edge_id
        else:
            conditions = names["repeat"]
            xy, yaw = repeat_poses(path, place["repeat"], int(place["seed"]))
            edge = np.full(len(xy), -1, np.int64)
            seed += 1  # other sensor noise and rain than the teach drive
        images = render_conditions(scene, rig, conditions, xy, yaw, seed, view, color)
        places = PlaceSet(images, conditions, xy, yaw, np.zeros(len(xy), np.int64), np.arange(len(xy)), edge)
    seconds = time.perf_counter() - started
    places.save(outputs["places"])
    n_images = places.images.shape[0] * places.images.shape[1]
    facts |= {"places": float(len(places)), "images": float(n_images), "seconds": seconds,
              "images_per_s": n_images / max(seconds, 1e-9)}
    log.info("split %s: %d places x %d conditions in %.1f s", split, len(places), len(places.conditions), seconds)
    write_json(outputs["stats"], {"split": split, "conditions": places.conditions, "image_shape": list(places.images.shape[2:]), **facts})
    _sheet(places, outputs["sheet"], f"{split}: {len(places)} places, {places.images.shape[3]}x{places.images.shape[2]} px")
    return facts
