"""The closed-loop check of a trained controller, route by route: which unseen routes it fails, where and how.

Usage (after ``train_controller`` built ``results/<region>/drive/<agent>/controller.ckpt``)::

    PYTHONPATH=src python benchmarks/check_failures.py --agent lp [--config config/config.yaml]
        [--also config/experiments/drive_paper.yaml] [--controller CKPT] [--routes 50]

Drives the check's routes (:func:`topoloc.drive.on_policy.closed_loop_check`: the same seeds, conditions and start
offsets; the controller alone, told the route's command or local path) and prints one row per failed route: where
it ended, the commands of its last 40 steps, its speed at the last step against the expert's lowest target speed
over the last second, its mean steering against the expert's over the last second, and the metres of the route's
lane shared with another road's carriageway (:func:`topoloc.drive.lane_rasters.shared_samples`). Then the totals: success
rate, failures by outcome, failures within 20 m of the start, failures under a turn command, and the median ratio
of the controller's steering to the expert's where the expert steers hard (|steer| > 0.3) in a failure's last
second: below 1, it under-steers; below 0, it steers the other way.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from topoloc.config import load_layered
from topoloc.drive.controller import TopoDLM, load_controller
from topoloc.drive.demonstrations import as_input, training_route
from topoloc.drive.expert import Expert, ExpertSettings
from topoloc.drive.on_policy import CHECK_STREAM, controller_input
from topoloc.drive.routes import make_simulator, random_drive_route, teach_route
from topoloc.drive.simulator import RUNNING, SUCCESS, Control
from topoloc.drive.topo_lp import CONTROLLERS
from topoloc.graph.road_graph import RoadGraph
from topoloc.place.topometric_map import COMMANDS


def drive_route(conf: dict, agent: str, model: TopoDLM, r: int, avoid: np.ndarray, graph: RoadGraph,
                osm: str | None) -> dict:
    """Check route ``r`` driven by ``model``: its outcome and the last steps' trace."""
    drive = conf["drive"]
    length = float(drive["demonstrations"]["route_length_m"])
    route = training_route(r, conf, avoid, lambda rng: random_drive_route(graph, conf, length, rng), stream=CHECK_STREAM)
    sim = make_simulator(osm, graph, route, conf)
    conditions = [str(c) for c in conf["place"]["repeat_conditions"]]
    condition = conditions[r % len(conditions)]
    seed = int(np.random.SeedSequence([int(drive["seed"]), CHECK_STREAM, r]).generate_state(1)[0])
    rng = np.random.default_rng([seed, 59])  # the start offsets of the check (on_policy.drive_on_policy)
    follow = drive["follow"]
    obs = sim.reset(condition, seed, float(rng.uniform(-1, 1) * follow["start_lateral_m"]),
                    float(rng.uniform(-1, 1) * follow["start_yaw_deg"]))
    expert = Expert(route, sim.spec, ExpertSettings.from_conf(drive["expert"]))
    expert.reset()
    color = bool(conf["place"]["image"]["color"])
    trace, status = [], RUNNING
    while status == RUNNING:
        label = expert.control(sim.state)
        told = controller_input(agent, route, sim.s, sim.centre, sim.state.yaw)
        control = Control(*model.act(as_input(obs.image, color), obs.speed, told))
        trace.append((sim.s, sim.lateral, obs.speed, route.command_at(sim.s), control.steer, label.steer,
                      expert.last_target))
        obs, status = sim.step(control)
    return {"route": r, "condition": condition, "outcome": status, "end_m": sim.s, "length_m": route.length_m,
            "shared_m": route.shared_m, "trace": np.array(trace)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="config/config.yaml")
    parser.add_argument("--also", nargs="*", default=[], help="config files merged over --config (later ones win)")
    parser.add_argument("--agent", choices=sorted(CONTROLLERS), default="lp")
    parser.add_argument("--controller", type=Path, help="checkpoint (default: the region's own)")
    parser.add_argument("--routes", type=int, help="check routes (default: drive.check.routes)")
    args = parser.parse_args()
    conf = load_layered(args.config, args.also)
    torch.set_num_threads(1)
    root = Path("results") / conf["region"]["name"]
    graph = RoadGraph.load(root / "graph" / "graph.graphml")
    osm = next((str(p) for p in (root / "osm").glob("region.*") if p.suffix != ".json"), None)
    model = load_controller(args.controller or root / "drive" / args.agent / "controller.ckpt",
                            cls=CONTROLLERS[args.agent]).eval()
    avoid = teach_route(graph, conf).xy
    routes = args.routes if args.routes is not None else int(conf["drive"]["check"]["routes"])
    rows = [drive_route(conf, args.agent, model, r, avoid, graph, osm) for r in range(routes)]
    failed = [row for row in rows if row["outcome"] != SUCCESS]
    print("| route | condition | outcome | ended at (m) | commands | speed / expert's target (m/s) | "
          "steer / expert's, last second | shared (m) |")
    print("|---|---|---|---|---|---|---|---|")
    ratios = []
    for row in failed:
        t = row["trace"]
        last = t[-10:]
        hard = np.abs(last[:, 5]) > 0.3
        ratios += list(last[hard, 4] / last[hard, 5])
        commands = ", ".join(COMMANDS[int(c)] for c in dict.fromkeys(t[-40:, 3]))
        print(f"| {row['route']} | {row['condition']} | {row['outcome']} | {row['end_m']:.0f} of {row['length_m']:.0f} | "
              f"{commands} | {last[-1, 2]:.1f} / {last[:, 6].min():.1f} | {last[:, 4].mean():+.2f} / {last[:, 5].mean():+.2f} | "
              f"{row['shared_m']:.0f} |")
    outcomes = {o: sum(r["outcome"] == o for r in failed) for o in dict.fromkeys(r["outcome"] for r in failed)}
    print(f"\nsuccess rate {1 - len(failed) / len(rows):.2f} of {len(rows)} routes; failures: {outcomes}")
    print(f"failures within 20 m of the start: {sum(r['end_m'] < 20 for r in failed)}; under a turn command: "
          f"{sum(bool(np.any(r['trace'][-40:, 3] != 0)) for r in failed)}; on routes with shared lane: "
          f"{sum(r['shared_m'] > 0 for r in failed)} (of {sum(r['shared_m'] > 0 for r in rows)} such routes)")
    if ratios:
        print(f"controller / expert steering where the expert steers hard in a failure's last second: "
              f"median {np.median(ratios):.2f} ({len(ratios)} steps)")


if __name__ == "__main__":
    main()
