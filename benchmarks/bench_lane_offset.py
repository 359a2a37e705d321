"""Where the trained controllers drive on the teach route: their offset from the lane, with ground-truth localization.

Usage (after ``snakemake all`` built ``results/<region>/drive/{dlm,lp}``)::

    python -m benchmarks.bench_lane_offset [--configfile config/config.yaml] [--condition overcast] [--bin-m 10]

Each trained controller (Topo-DLM, Topo-LP) drives the evaluation route (the teach route's first
``drive.follow.length_m``) once from the lane's centre, localized by ground truth and under the teach drive's speed
limit as in ``follow_route``. Per ``--bin-m`` of the route: the carriageway's width and whether it is one-way (the lane
is its middle there, a quarter of it right of the centre line on marked two-way roads), the vehicle's mean offset from
the lane (m, + right), the controller's steering and the expert's at the same pose (the correction it would make).
A controller that holds an offset the expert would correct at full lock has learnt another lane than the route's: the
measurement behind "Why the default run finishes no drive" in docs/route_following.md.

A third drive, ``path``, is Topo-LP's ceiling: no network, the expert's pure-pursuit law on the local path Topo-LP is
told (:func:`topoloc.drive.local_path.map_path` of the localized vertex, the map's path-integrated chain) placed at
the vertex's true pose on the teach drive, so the vehicle's offset and heading off the teach drive there are known
exactly (what Topo-LP must read from its image). Where it finishes and a controller does not, the map's path was
enough and the controller's estimate of where the vehicle stands is what fails.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc.config import load
from topoloc.drive.agents import DLMAgent, LPAgent, TeachImages, controller_agent
from topoloc.drive.camera import image_shape
from topoloc.drive.controller import AGENT_NAMES
from topoloc.drive.demonstrations import as_input
from topoloc.drive.episodes import speed_limit_ahead, teach_controls
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.local_path import chain_frame, map_path
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.repeat_routes import repeat_routes
from topoloc.drive.routes import make_simulator, teach_route
from topoloc.drive.simulator import RUNNING, Control, Simulator, VehicleSpec, VehicleState
from topoloc.drive.topo_lp import load_controller
from topoloc.graph.road_graph import RoadGraph
from topoloc.place.topometric_map import TopometricMap


def _pursuit(points: np.ndarray, state: VehicleState, spec: VehicleSpec, settings: ExpertSettings) -> float:
    """The expert's pure-pursuit steering on a polyline (map metres): it aims ``max(min_lookahead_m, lookahead_s v)``
    along the polyline beyond its point nearest the rear axle."""
    rear = np.array([state.x, state.y])
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
    look = max(settings.min_lookahead_m, settings.lookahead_s * state.v)
    at = arc[int(np.argmin(np.hypot(*(points - rear).T)))] + look
    target = np.array([np.interp(at, arc, points[:, 0]), np.interp(at, arc, points[:, 1])])
    alpha = (np.arctan2(*(target - rear)[::-1]) - state.yaw + np.pi) % (2 * np.pi) - np.pi
    delta = np.arctan2(2.0 * spec.wheelbase_m * np.sin(alpha), look)
    return float(np.clip(delta / np.radians(spec.max_steer_deg), -1.0, 1.0))


class PathOracle:
    """Pure pursuit on the localized vertex's local path, placed at the vertex's true pose (the module docstring), at the
    expert's speed."""

    def __init__(self, topo: TopometricMap, sim: Simulator, expert: Expert) -> None:
        self.topo, self.sim, self.expert = topo, sim, expert
        self._paths: dict[int, np.ndarray] = {}

    def _placed(self, vertex: int) -> np.ndarray:
        """The vertex's local path (map metres) at the vertex's true pose."""
        at, yaw = chain_frame(self.topo.gt_xy, vertex)  # the frame map_path takes, on the teach drive's true path
        local = map_path(self.topo.xy, vertex)
        c, s = np.cos(yaw), np.sin(yaw)
        return at + np.column_stack([local[:, 0] * c - local[:, 1] * s, local[:, 0] * s + local[:, 1] * c])

    def act(self, image: np.ndarray, speed: float, vertex: int) -> Control:
        if vertex not in self._paths:
            self._paths[vertex] = self._placed(vertex)
        state = self.sim.state
        return Control(_pursuit(self._paths[vertex], state, self.sim.spec, self.expert.settings),
                       self.expert.control(state).throttle)


def drive_once(conf: dict, root: Path, agent: str, condition: str) -> tuple[pd.DataFrame, str]:
    """One ground-truth drive of the evaluation route by controller ``agent`` (or the ``path`` oracle): a row per step
    and the outcome."""
    drive, place = conf["drive"], conf["place"]
    graph = RoadGraph.load(root / "graph" / "graph.graphml")
    part = repeat_routes(teach_route(graph, conf), TopometricMap.load(root / "topometric_map" / "map.npz"),
                         drive["follow"]["length_m"], 1)[0]
    osm = next((root / "osm").glob("region.*"), None)
    sim = make_simulator(str(osm) if osm else None, graph, part.route, conf)
    expert = Expert(part.route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    _, teach_speed = teach_controls(sim, expert, place["teach_condition"], int(drive["seed"]), part.lane_s)
    ahead = drive["follow"]["teach_speed_ahead_m"]
    limit = None if ahead is None else speed_limit_ahead(teach_speed, part.lane_s, float(ahead))
    if agent == "path":
        controller: PathOracle | LPAgent | DLMAgent = PathOracle(part.topo, sim, expert)
    else:
        model = load_controller(root / "drive" / agent / "controller.ckpt", image_shape(conf), "drive.camera")
        teach = TeachImages(sim, part.topo, place["teach_condition"], int(drive["seed"]), bool(place["image"]["color"]))
        controller = controller_agent(model, part.topo, teach)
    localization, gain = GroundTruth(part.lane_s), float(drive["expert"]["speed_gain"])
    oneway = graph.edges.oneway.to_numpy() != 0
    obs, status, rows = sim.reset(condition, int(drive["seed"])), RUNNING, []
    expert.reset()
    while status == RUNNING:
        label = expert.control(sim.state)
        vertex, _ = localization.update(obs.image, 0.0, sim)
        control = controller.act(as_input(obs.image, bool(place["image"]["color"])), obs.speed, vertex)
        if limit is not None:
            control = Control(control.steer, min(control.throttle, gain * (float(limit[vertex]) - obs.speed)))
        i = part.route.index(sim.s)
        rows.append({"s": sim.s, "lateral_m": sim.lateral, "steer": control.steer, "expert_steer": label.steer,
                     "width_m": float(part.route.width[i]), "oneway": bool(oneway[part.route.edge[i]])})
        obs, status = sim.step(control)
        if obs is None:
            break
    return pd.DataFrame(rows), status


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configfile", default="config/config.yaml")
    parser.add_argument("--condition", default="overcast")
    parser.add_argument("--bin-m", type=float, default=10.0)
    add_out_option(parser, "bench_lane_offset")
    args = parser.parse_args()
    torch.set_num_threads(1)
    with markdown_copy(args.out):
        config = load(Path(args.configfile))
        conf = {"drive": config["drive"], "place": config["place"], "render": config["render"]}
        root = Path("results") / config["region"]["name"]
        for agent in ("dlm", "lp", "path"):
            steps, outcome = drive_once(conf, root, agent, args.condition)
            steps["bin"] = (steps.s // args.bin_m * args.bin_m).astype(int)
            table = steps.groupby("bin").agg(width_m=("width_m", "first"), oneway=("oneway", "first"),
                                             lateral_m=("lateral_m", "mean"), steer=("steer", "mean"),
                                             expert_steer=("expert_steer", "mean"))
            name = AGENT_NAMES.get(agent, "Topo-LP's local path, pose known (no network)")
            print(f"## {name} (ground truth, {args.condition}): {outcome} after {steps.s.iloc[-1]:.0f} m\n")
            print(table.rename_axis("from m").to_markdown(floatfmt=".2f"))
            held = steps[(steps.s > 20) & (np.abs(steps.lateral_m) > 1.0)]
            print(f"\nsteps more than 1 m off the lane after 20 m: {len(held)} of {len(steps)}; the expert's mean "
                  f"|steering| there {np.abs(held.expert_steer).mean() if len(held) else 0.0:.2f}, the controller's "
                  f"{np.abs(held.steer).mean() if len(held) else 0.0:.2f}\n")


if __name__ == "__main__":
    main()
