"""Route-following benchmark: closed-loop simulator speed on one core, and the success rates against the targets.

Usage (after ``snakemake all`` built ``results/<region>/drive/follow``)::

    python -m benchmarks.bench_drive [--configfile config/config.yaml] [--steps 300] [--localizer place_loop]
        [--agents dlm,lp] [--rounds 3]

1. **Speed**: on the evaluation route, one torch thread, the closed loop of each agent (Topo-DLM, Topo-LP) with the
   configured place localizer (render the camera image, embed it and localize on the topometric map, run the
   controller, and for a Topo-LP trained with ``path_frame: aligned`` its pose tracker on the teach drive's images,
   step the vehicle; the teach images are rendered before the clock starts, as a teach drive records them), then its
   parts alone: rendering, rendering plus the controller (and tracker), rendering plus the
   localization; each timed once a round, the median of the rounds reported with their range (the machine's speed
   drifts). Target (issue 39): at least 100 closed-loop steps per second at the controller's image size.
2. **Success rates**: the ``follow_route`` summary per agent and condition, checked against the issue's
   targets (Topo-DLM and Topo-LP with retrieval localization: mean success >= 0.8 and every condition >= 0.6,
   ahead of replay).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc.config import load
from topoloc.drive.agents import TeachImages, controller_agent
from topoloc.drive.camera import image_shape
from topoloc.drive.controller import AGENT_NAMES
from topoloc.drive.demonstrations import as_input
from topoloc.drive.follow_route import place_localization
from topoloc.drive.localization_adapters import GroundTruth
from topoloc.drive.repeat_routes import vertex_lane_s
from topoloc.drive.routes import evaluation_route, make_simulator
from topoloc.drive.simulator import RUNNING, Control
from topoloc.drive.topo_lp import load_controller
from topoloc.graph.road_graph import RoadGraph
from topoloc.place.network import load_model
from topoloc.place.topometric_map import TopometricMap

TARGET_STEPS_PER_S = 100.0


def speed(conf: dict, root: Path, steps: int, localizer: str, agents: list[str], rounds: int = 3) -> dict[str, list[float]]:
    """Steps per second of the closed loop of each of ``agents`` (the region's controllers) and of its parts (one
    thread), in each of ``rounds`` rounds (each round times every part once: a machine whose speed drifts slows all
    parts alike, and the median over the rounds is the figure)."""
    torch.set_num_threads(1)
    graph = RoadGraph.load(root / "graph" / "graph.graphml")
    route = evaluation_route(graph, conf)
    osm = next((root / "osm").glob("region.*"), None)
    sim = make_simulator(str(osm) if osm else None, graph, route, conf)
    topo = TopometricMap.load(root / "topometric_map" / "map.npz")
    lane_s = vertex_lane_s(route, topo)
    place = conf["place"]
    color = bool(place["image"]["color"])
    teach = TeachImages(sim, topo, place["teach_condition"], int(conf["drive"]["seed"]), color)
    for vertex in range(len(topo)):  # the teach drive's images are its recording, not the repeat drive's work
        teach(vertex)
    retrieval = load_model(root / "retrieval" / "model.ckpt")
    condition = place["repeat_conditions"][0]
    runs: list[tuple[str, str | None, str | None]] = [("render only", None, None), ("render + localization", None, "place")]
    for agent in agents:
        name = AGENT_NAMES[agent]
        runs += [(f"{name}: render + controller", agent, "ground_truth"), (f"{name}: closed loop", agent, "place")]
    models = {agent: load_controller(root / "drive" / agent / "controller.ckpt", image_shape(conf), "drive.camera")
              for agent in agents}
    out: dict[str, list[float]] = {name: [] for name, _, _ in runs}
    for name, agent, loc in [run for _ in range(rounds) for run in runs]:
        model = models[agent] if agent else None
        localization = (place_localization(localizer, topo, retrieval, conf) if loc == "place"
                        else GroundTruth(lane_s) if loc else None)
        done, status, driver = 0, RUNNING, None
        started = time.perf_counter()
        while done < steps:
            if done == 0 or status != RUNNING:
                obs = sim.reset(condition, 1)
                if localization is not None:
                    localization.start(np.random.default_rng(0))
                driver = None if model is None else controller_agent(model, topo, teach)
            vertex = 0
            image = as_input(obs.image, color)
            if localization is not None:
                vertex, _ = localization.update(image, obs.speed * sim.spec.dt, sim)
            control = driver.act(image, obs.speed, vertex) if driver is not None else Control(0.0, 0.3)
            obs, status = sim.step(control)
            done += 1
        out[name].append(done / (time.perf_counter() - started))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configfile", default="config/config.yaml")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--localizer", default="place_loop")
    parser.add_argument("--agents", default="dlm,lp", help="controllers of the region to time, comma-separated")
    parser.add_argument("--rounds", type=int, default=3, help="times each part is timed; the median is reported")
    add_out_option(parser, "bench_drive")
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error(f"--rounds must be at least 1, not {args.rounds}")
    with markdown_copy(args.out):
        config = load(Path(args.configfile))
        conf = {"drive": config["drive"], "place": config["place"], "render": config["render"]}
        root = Path("results") / config["region"]["name"]
        agents = [a for a in args.agents.split(",") if a]
        timed = speed(conf, root, args.steps, args.localizer, agents, args.rounds)
        rates = {name: float(np.median(values)) for name, values in timed.items()}
        height, width, _ = image_shape(conf)
        size = f"{width}x{height}"
        print(f"## Closed-loop steps per second (one thread, {size} images, {args.steps} steps each, median of "
              f"{args.rounds} rounds)")
        for name, value in rates.items():
            print(f"- {name}: {value:.1f} steps/s ({min(timed[name]):.1f}-{max(timed[name]):.1f})")
        for agent in agents:
            rate = rates[f"{AGENT_NAMES[agent]}: closed loop"]
            verdict = "met" if rate >= TARGET_STEPS_PER_S else "MISSED"
            print(f"{AGENT_NAMES[agent]}: target >= {TARGET_STEPS_PER_S:.0f} closed-loop steps/s: {verdict}")
        summary_path = root / "drive" / "follow" / "summary.csv"
        result = {"steps_per_s": rates}
        if summary_path.is_file():
            summary = pd.read_csv(summary_path)
            table = summary.pivot_table(index="agent", columns="condition", values="success_rate", sort=False)
            table.insert(0, "Mean", table.mean(axis=1))
            print("\n## Success rate per condition (follow_route)\n")
            print(table.to_markdown(floatfmt=".2f"))
            learned = [a for a in table.index if a.startswith("Topo-") and "ground truth" not in a]
            for agent in learned:
                ok = table.loc[agent, "Mean"] >= 0.8 and table.loc[agent].drop("Mean").min() >= 0.6
                print(f"{agent}: target mean >= 0.8 and every condition >= 0.6: {'met' if ok else 'MISSED'}")
            result["success"] = {a: table.loc[a].to_dict() for a in table.index}
        print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
