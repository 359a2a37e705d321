"""The routes of the drive stages: the teach route (evaluation), the training routes, and their simulators.

* The **teach route** is the path of render route ``place.route`` (:func:`topoloc.render.drives.drive_path`,
  the route of the ``render_places`` teach drive and so of the topometric map), as a chain of road edges
  whose lane (:mod:`topoloc.drive.drive_route`) ends where that path ends.
* **Training routes** are random walks (:func:`topoloc.motion.route.random_route`, one-way roads respected,
  cut where they turn back at a dead end) seeded by ``drive.seed``, the route index and the attempt; a walk whose lane
  runs on other roads' carriageways for more than ``drive.lane.max_shared_m`` is drawn again (the images could not
  show which road to keep to). A share of them may be drawn through the map's sharp turns instead
  (:mod:`topoloc.drive.turn_routes`, ``drive.demonstrations.sharp_turn_share``).
* A route's **simulator** renders the scene around its lane (``render.buildings``, ``render.view_distance_m``)
  with the controller's camera (:func:`topoloc.drive.camera.drive_rig`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from topoloc.drive.camera import drive_rig
from topoloc.drive.drive_route import DriveRoute, build_route
from topoloc.drive.route_planning import route_froms
from topoloc.drive.simulator import Simulator, VehicleSpec
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.motion.route import random_route
from topoloc.render.drives import drive_path
from topoloc.render.scene import scene_for_path


def route_of_edges(graph: RoadGraph, edges: list[int], froms: list[int], conf: dict[str, Any],
                   where: str = "route") -> DriveRoute:
    """The drive route of a chain of edges with the ``drive.lane`` and ``place.command`` settings of ``conf``.

    InputError naming ``drive.lane.min_radius_m`` when it is below the vehicle's turning radius (the expert could
    not follow the lane)."""
    lane, cmd = conf["drive"]["lane"], conf["place"]["command"]
    spec = VehicleSpec.from_conf(conf["drive"])
    turning = spec.wheelbase_m / np.tan(np.radians(spec.max_steer_deg))
    if float(lane["min_radius_m"]) < turning:
        raise InputError("drive.lane.min_radius_m", f"{lane['min_radius_m']} m is below the vehicle's turning radius "
                         f"({turning:.2f} m at {spec.max_steer_deg} deg and a {spec.wheelbase_m} m wheelbase)")
    return build_route(graph, edges, froms, float(lane["smoothing_m"]), float(lane["margin_m"]), float(cmd["distance_m"]),
                       float(cmd["lookahead_m"]), float(cmd["straight_deg"]), where, float(lane["min_radius_m"]))


def teach_route(graph: RoadGraph, conf: dict[str, Any]) -> DriveRoute:
    """The whole teach route (see the module docstring)."""
    path = drive_path(graph, conf["render"], int(conf["place"]["route"]))
    labels = path.edge_id.tolist()
    edges = [int(e) for k, e in enumerate(labels) if k == 0 or e != labels[k - 1]]  # the walk may pass a road twice
    route = route_of_edges(graph, edges, route_froms(graph, edges, path.xy[0]), conf, "place.route")
    end, _, _ = route.project(path.xy[-1], path.length_m, 50.0, 50.0)
    return route.cut(end)


def evaluation_route(graph: RoadGraph, conf: dict[str, Any]) -> DriveRoute:
    """The driven part of the teach route: its first ``drive.follow.length_m`` metres."""
    route = teach_route(graph, conf)
    length = conf["drive"]["follow"]["length_m"]
    return route.cut(float(length)) if length is not None else route


def random_drive_route(graph: RoadGraph, conf: dict[str, Any], length_m: float, rng: np.random.Generator) -> DriveRoute | None:
    """A random route of about ``length_m`` (None when the walk is too short, cannot be built, or runs on other roads'
    carriageways for more than ``drive.lane.max_shared_m``)."""
    edges, froms = random_route(graph, length_m, rng)
    for i in range(1, len(edges)):
        if edges[i] == edges[i - 1]:  # turned back at a dead end
            edges, froms = edges[:i], froms[:i]
            break
    return drive_route_of_walk(graph, conf, edges, froms, length_m)


def drive_route_of_walk(graph: RoadGraph, conf: dict[str, Any], edges: list[int], froms: list[int],
                        length_m: float, lead: tuple[int, float] | None = None) -> DriveRoute | None:
    """The training route of a walk (roads and the node each is entered from), cut to ``length_m`` from its start, or
    with ``lead`` = (road, metres) from that many metres before its lane first reaches that road; None when the walk
    is under half of ``length_m``, its lane cannot be built, or it runs on other roads' carriageways for more than
    ``drive.lane.max_shared_m``."""
    if not edges or float(graph.edges.length_m.iloc[edges].sum()) < 0.5 * length_m:
        return None
    try:
        route = route_of_edges(graph, edges, froms, conf)
    except InputError:
        return None
    start = 0.0
    if lead is not None:
        reach = np.flatnonzero(route.edge == lead[0])
        start = max(0.0, float(route.s[reach[0]]) - float(lead[1])) if len(reach) else 0.0
    if start > 0.0 or route.length_m > length_m:
        route = route.part(start, length_m)
    shared = conf["drive"]["lane"]["max_shared_m"]
    return None if shared is not None and route.shared_m > float(shared) else route


def make_simulator(osm: str | None, graph: RoadGraph, route: DriveRoute, conf: dict[str, Any]) -> Simulator:
    """The simulator of ``route``: its scene, the controller's camera (:func:`~topoloc.drive.camera.drive_rig`), the ``drive`` vehicle and
    episode rules."""
    render = conf["render"]
    scene = scene_for_path(osm, graph, route.xy, {**render["buildings"], "view_distance_m": float(render["view_distance_m"])},
                           int(render["seed"]))
    return Simulator(route, scene, drive_rig(conf), VehicleSpec.from_conf(conf["drive"]), float(render["view_distance_m"]))
