"""Fixtures of the drive tests: the hand-made town of the render tests, its routes, and a straight road."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from tests.conftest import make_config, write_osm
from tests.render.conftest import lonlat, town  # noqa: F401 (the town fixture, re-exported)
from topoloc.drive.controller import WAYPOINT_SCALE_M, TopoDLM, waypoint_targets
from topoloc.drive.controller_training import DemoData, fit, path_noise
from topoloc.drive.demonstrations import LOCAL_PATH_M, Demonstrations, record
from topoloc.drive.drive_route import DriveRoute, build_route
from topoloc.drive.expert import Expert, ExpertSettings, NoiseSettings
from topoloc.drive.repeat_routes import vertex_lane_s
from topoloc.drive.route_planning import plan_route
from topoloc.drive.simulator import SUCCESS, Simulator, VehicleSpec
from topoloc.graph.from_osm import build_road_graph
from topoloc.graph.road_graph import RoadGraph
from topoloc.place.topometric_map import TopometricMap
from topoloc.render.rig import StereoRig
from topoloc.render.scene import Scene, scene_for_path

#: Node pairs of the town's evaluation routes (grid corners and edge midpoints, by position): straight on,
#: a right turn, a left turn.
TOWN_ROUTES = {"straight": ((0.0, 150.0), (300.0, 150.0)), "right": ((0.0, 150.0), (150.0, 0.0)),
               "left": ((150.0, 0.0), (0.0, 150.0))}


def drive_conf(**sections) -> dict:
    """The ``drive`` slice (schema defaults) with sections updated."""
    conf = make_config()["drive"]
    for key, value in sections.items():
        conf[key] = {**conf[key], **value} if isinstance(value, dict) else value
    return conf


def node_at(graph: RoadGraph, x: float, y: float) -> int:
    """The graph node nearest to the town position (x, y) metres from its south-west corner."""
    ref = graph.nodes[["x", "y"]].to_numpy(float)
    origin = ref.min(axis=0)
    return int(graph.nodes.index[int(np.argmin(np.hypot(*(ref - origin - [x, y]).T)))])


def town_route(graph: RoadGraph, name: str, drive: dict) -> DriveRoute:
    """One of :data:`TOWN_ROUTES` as a drive route."""
    (a, b) = TOWN_ROUTES[name]
    edges, froms = plan_route(graph, node_at(graph, *a), node_at(graph, *b))
    return build_route(graph, edges, froms, drive["lane"]["smoothing_m"], drive["lane"]["margin_m"],
                       min_radius_m=drive["lane"]["min_radius_m"])


@pytest.fixture(scope="session")
def town_graph(town) -> RoadGraph:  # noqa: F811 (the fixture re-exported above)
    """The town's road graph."""
    return RoadGraph.load(town["graph"])


def route_scene(osm: Path, graph: RoadGraph, route: DriveRoute) -> Scene:
    """The buildings and roads around a route (default render settings)."""
    render = make_config()["render"]
    return scene_for_path(str(osm), graph, route.xy, {**render["buildings"], "view_distance_m": 100.0}, 0)


@pytest.fixture(scope="session")
def straight_road(tmp_path_factory) -> dict:
    """A straight two-way residential road of 400 m (with a crossing side street at 200 m) and its graph."""
    tmp = tmp_path_factory.mktemp("straight")
    nodes = {1: lonlat(0.0, 0.0), 2: lonlat(200.0, 0.0), 3: lonlat(400.0, 0.0), 4: lonlat(200.0, -60.0),
             5: lonlat(200.0, 60.0)}
    ways = [(10, [1, 2, 3], {"highway": "residential", "name": "Long"}),
            (11, [4, 2, 5], {"highway": "residential", "name": "Cross"})]
    osm = write_osm(tmp / "straight.osm", nodes, ways)
    graph, _ = build_road_graph(str(osm), ["residential"], 20.0)
    return {"osm": osm, "graph": graph}


@pytest.fixture(scope="session")
def straight(straight_road):
    """The drive settings of the straight-road controllers (small network and budget) and the simulator of 260 m of
    the road."""
    drive = drive_conf(train={"batch_size": 32, "batches_per_epoch": 15, "max_epochs": 6, "max_time_min": None,
                              "accelerator": "cpu", "log_model": False, "log_every_n_steps": 5},
                       network={"channels": [16, 24, 32], "hidden": 64, "dropout": 0.1, "dlm_command": "discrete",
                                "output": {"dlm": "steer", "lp": "waypoints"}},
                       demonstrations={"val_routes": 1})
    return drive, road_simulator(straight_road, drive, 260.0)


def road_simulator(straight_road: dict, drive: dict, length_m: float) -> Simulator:
    """The simulator of the first ``length_m`` of the straight road's lane (64 x 48 camera)."""
    graph = straight_road["graph"]
    edges, froms = plan_route(graph, node_at(graph, 0.0, 60.0), node_at(graph, 400.0, 60.0))
    route = build_route(graph, edges, froms, drive["lane"]["smoothing_m"], drive["lane"]["margin_m"],
                       min_radius_m=drive["lane"]["min_radius_m"]).cut(length_m)
    return Simulator(route, route_scene(straight_road["osm"], graph, route), StereoRig.kitti(64, 48, 0.54, 1.65),
                     VehicleSpec.from_conf(drive), 100.0)


@pytest.fixture(scope="session")
def straight_demos(straight):
    """The expert's noisy drives of the straight road under clear_noon: two routes to train on, one to validate."""
    drive, sim = straight
    expert = Expert(sim.route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    noise = NoiseSettings.from_conf({**drive["noise"], "share": 0.3})
    parts = []
    for r in range(3):  # two routes' worth of frames to train on, the third to validate
        demo, status = record(sim, expert, "clear_noon", 10 + r, noise, 2, True, ["clear_noon"], r)
        assert status == SUCCESS
        parts.append(demo)
    return Demonstrations.concat(parts)


@pytest.fixture(scope="session")
def trained_dlm(straight, straight_demos, tmp_path_factory) -> tuple:
    """Topo-DLM fitted on the straight road's demonstrations: the model, its metrics and its checkpoint."""
    drive, _ = straight
    path = tmp_path_factory.mktemp("dlm") / "controller.ckpt"
    model, _history, metrics = fit(drive, straight_demos, str(path))
    return model, metrics, path


#: The validation steps the steering error is measured on: the expert's corrections, steering at least this much (on a
#: straight road a zero answer is right on every other step).
CORRECTION_STEER = 0.1


def _val_data(drive: dict, demos: Demonstrations, agent: str) -> DemoData:
    return DemoData(demos, int(drive["demonstrations"]["val_routes"]), drive["train"],
                    float(drive["vehicle"]["max_speed_mps"]), path_noise(drive, agent))


def zero_answer_errors(drive: dict, demos: Demonstrations) -> dict[str, float]:
    """The errors of :func:`val_errors` for a controller that answers zero (no steering, every lane point at the
    vehicle)."""
    val = _val_data(drive, demos, "dlm").val_idx
    corrections = val[np.abs(demos.steer[val]) >= CORRECTION_STEER]
    return {"steer": float(np.abs(demos.steer[corrections]).mean()),
            "lane_points_m": float(np.abs(waypoint_targets(demos.path[val])).mean() * WAYPOINT_SCALE_M)}


@torch.no_grad()
def val_errors(model: TopoDLM, drive: dict, demos: Demonstrations, agent: str = "dlm") -> dict[str, float]:
    """Mean absolute errors of ``model`` on the validation steps: ``steer`` on the expert's corrections
    (:data:`CORRECTION_STEER`) and, for a ``waypoints`` output, ``lane_points_m``: the coordinates of its lane points."""
    data = _val_data(drive, demos, agent)
    model.eval()
    steer, points, label = [], [], []
    for images, speed, condition, target in data.val_dataloader():
        chosen, _ = model._outputs(model._shrink(images.permute(0, 3, 1, 2).float()), speed, condition)
        steer.append((model._control(chosen, speed)[0] - target[:, 0]).abs())
        label.append(target[:, 0])
        if model.n_outputs > 2:
            points.append((chosen[:, :-1] - target[:, 2:]).abs().mean(dim=1) * WAYPOINT_SCALE_M)
    out = {"steer": float(torch.cat(steer)[torch.cat(label).abs() >= CORRECTION_STEER].mean())}
    return out | ({"lane_points_m": float(torch.cat(points).mean())} if points else {})


class ConstantSteer:
    """A baseline controller: always the same steering (0: straight on, 1: full left), with the throttle that holds
    the expert's cruise speed."""

    def __init__(self, steer: float, drive: dict) -> None:
        self.steer, self.cruise, self.gain = steer, float(drive["expert"]["cruise_mps"]), float(drive["expert"]["speed_gain"])

    def act(self, image, speed: float, command) -> tuple[float, float]:
        return self.steer, float(np.clip(self.gain * (self.cruise - speed), -1.0, 1.0))


#: The trivial controllers every closed-loop bound on a trained controller must fail: steering fixed at these values.
BASELINES = {"always straight": 0.0, "always left": 1.0}


def lane_map(route, step_m: float = 1.0) -> TopometricMap:
    """A topometric map with a vertex every metre of the lane (ground truth = path integration)."""
    s = np.arange(0.0, route.length_m, step_m)
    xy = np.stack([route.point(v) for v in s])
    command = np.array([route.command_at(v) for v in s])
    return TopometricMap(np.zeros((len(s), 4), np.float32), np.zeros((len(s), 4), np.float32), xy, command, xy, "clear_noon")


def right_turn(town, town_graph) -> tuple:
    """The town's 175 m route with its right turn: drive and stage config, route, simulator, lane map, vertex arcs."""
    drive = drive_conf(follow={"start_lateral_m": 0.0, "start_yaw_deg": 0.0})
    conf = {"drive": drive, "place": make_config()["place"]}
    route = town_route(town_graph, "right", drive).cut(175.0)
    sim = Simulator(route, route_scene(town["osm"], town_graph, route), StereoRig.kitti(64, 48, 0.54, 1.65),
                    VehicleSpec.from_conf(drive), 100.0)
    topo = lane_map(route)
    return drive, conf, route, sim, topo, vertex_lane_s(route, topo)


def tiny_demos(routes: list[int], steps: int = 3, shape: tuple[int, int, int] = (4, 6, 3),
               conditions: tuple[str, ...] = ("clear_noon", "rain"), tag: float = 0.0) -> Demonstrations:
    """``steps`` steps on each of ``routes``, every step told apart by its ``speed`` (``tag`` + its index) and image."""
    n = len(routes) * steps
    index = np.arange(n)
    images = np.stack([np.full(shape, (int(tag) * 37 + i) % 256, np.uint8) for i in index])
    steer, throttle, target_speed, lateral = np.zeros((4, n), np.float32)
    return Demonstrations(images, list(conditions), np.repeat(np.asarray(routes, np.int64), steps),
                          index % len(conditions), (tag + index).astype(np.float32), np.zeros(n, np.int64), steer,
                          throttle, target_speed, np.zeros(n, bool), np.zeros((n, 2)), np.zeros(n), lateral,
                          np.zeros((n, LOCAL_PATH_M, 2), np.float32))
