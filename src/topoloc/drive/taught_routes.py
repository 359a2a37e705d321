"""Teach and repeat on any route: the topometric map of a route's teach drive, made in memory the way the pipeline
makes the teach route's (``render_places`` teach, ``build_topometric_map``), so a controller can be driven with a
localization on routes the pipeline never taught (``benchmarks.bench_drive_maps --teach-repeat``: maps left out).

The expert drives the route once under ``place.teach_condition`` (no noise, from the lane's start). Every
``every_steps``-th control step is a vertex: the controller camera's image there cut to the place images' window
(:func:`topoloc.drive.camera.place_window`, the camera the place images are rendered with) and embedded by the
retrieval network, its raw-correlation descriptor and its position from the teach drive's path through the odometry
noise model, as the pipeline's map (:func:`topoloc.place.topometric_map.teach_vertices`), and the route's command at the vehicle's
progress along the lane (the rule of the topometric map's commands, :mod:`topoloc.drive.drive_route`). Beside the
map: each vertex's progress along the lane (what :class:`topoloc.drive.localization_adapters.GroundTruth` reads) and
the expert's target speed there (the speed limit of :func:`topoloc.drive.episodes.speed_limit_ahead`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from topoloc.drive.camera import place_window
from topoloc.drive.demonstrations import as_input
from topoloc.drive.expert import Expert
from topoloc.drive.simulator import RUNNING, Simulator
from topoloc.place.topometric_map import TopometricMap, teach_vertices


@dataclass(frozen=True)
class TaughtRoute:
    """The map of a route's teach drive, each vertex's progress along the lane (m, non-decreasing), the expert's
    target speed there (m/s) and the teach drive's outcome (a route the expert did not finish cannot be repeated)."""

    topo: TopometricMap
    lane_s: NDArray[np.float64]
    teach_speed: NDArray[np.float64]
    outcome: str


def teach_map(sim: Simulator, expert: Expert, retrieval: Any, conf: dict[str, Any], seed: int,
              every_steps: int = 2) -> TaughtRoute:
    """The expert's teach drive of ``sim``'s route and its topometric map (see the module docstring; ``conf``: the
    ``drive``, ``place`` and ``render`` slices; ``retrieval``: the place network, its embeddings in the map)."""
    place = conf["place"]
    color = bool(place["image"]["color"])
    rows, cols = place_window(conf)
    obs = sim.reset(str(place["teach_condition"]), int(seed))
    expert.reset()
    images, xy, yaw, s, speed, status = [], [], [], [], [], RUNNING
    while status == RUNNING:
        control = expert.control(sim.state)
        if sim.t % max(1, int(every_steps)) == 0:
            images.append(as_input(obs.image, color)[rows, cols])
            xy.append(sim.centre)
            yaw.append(float(sim.state.yaw))
            s.append(sim.s)
            speed.append(float(expert.last_target))
        next_obs, status = sim.step(control)
        if next_obs is None:
            break
        obs = next_obs
    stack = np.stack(images)
    command = np.array([int(sim.route.command_at(v)) for v in s], np.int64)
    topo, _ = teach_vertices(stack, retrieval.embed(stack), np.asarray(xy), np.asarray(yaw), command,
                             str(place["teach_condition"]), place, int(seed))
    return TaughtRoute(topo, np.maximum.accumulate(np.asarray(s, float)), np.asarray(speed, float), status)
