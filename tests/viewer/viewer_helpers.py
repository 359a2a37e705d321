"""A small viewer for the viewer's tests: a grid map placed in Helsinki, a drive along a route, two localizers."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "localization"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "trajectory"))

from localization_helpers import irregular_grid, route_track

from topoloc.config import load
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry, poses_from_planar
from topoloc.registry import make
from topoloc.viewer.drive_view import drive_data
from topoloc.viewer.page import write_viewer

ROUTE = [0, 1, 6, 7, 8, 13, 14, 9, 4]
OFFSET = np.array([385000.0, 6670000.0])  # the grid placed in Helsinki, EPSG:3067


def small_drive():
    """The graph (in Helsinki), the true track, the odometry and the config."""
    graph, _ = irregular_grid()
    graph.nodes["x"] += OFFSET[0]
    graph.nodes["y"] += OFFSET[1]
    graph.geometry = [g + OFFSET for g in graph.geometry]
    xy = route_track(graph, ROUTE)
    step = np.diff(xy, axis=0)
    yaw = np.append(np.unwrap(np.arctan2(step[:, 1], step[:, 0])), 0.0)
    yaw[-1] = yaw[-2]
    odometry = Odometry.from_poses(poses_from_planar(xy - xy[0], yaw))
    conf = load(None, {"viewer": {"belief_every_m": 10.0, "heat_points": 50}})
    return graph, xy, odometry, conf


def answers_of(graph, odometry, conf, names=("metric", "hmm")) -> pd.DataFrame:
    """Each localizer's run from the first frame, as an answers table (with an extra column, as later versions may add)."""
    loc = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    road = RoadMap(graph, loc["localization"]["decode"]["u_turns"], loc["localization"]["decode"]["max_skip_m"])
    tables = []
    for name in names:
        localizer = make(name)
        observations = localizer.observe(odometry, road, loc)
        localizer.reset(road, loc)
        track = localizer.run(observations.items)
        tables.append(pd.DataFrame({"start": 0, "localizer": name, "frame": observations.frame, "state": track.state,
                                    "confidence": track.confidence, "x": track.xy[:, 0], "y": track.xy[:, 1],
                                    "top2_state": -1}))
    return pd.concat(tables, ignore_index=True)


def write_small_viewer(path: Path):
    """Write the small viewer to ``path``; its data and the graph."""
    graph, xy, odometry, conf = small_drive()
    answers = answers_of(graph, odometry, conf)
    data = drive_data("test drive", graph, odometry, answers, conf, xy, starts=[0, len(xy) // 2],
                      localized_m={"metric": 150.0, "hmm": 200.0, "oracle": 120.0})
    write_viewer(path, graph, data)
    return data, graph, xy


def embedded(path: Path) -> dict:
    """The JSON data block of a written viewer."""
    text = Path(path).read_text(encoding="utf-8")
    block = re.search(r'<script type="application/json" id="topoloc-data">(.*?)</script>', text, re.S).group(1)
    return json.loads(block.replace("<\\/", "</"))


EPISODES = ["0/night/0/lp/ground_truth", "0/night/0/replay/place_loop", "0/fog/0/replay/place_loop"]


def write_repeat_inputs(folder: Path) -> dict[str, str]:
    """The inputs of the teach-and-repeat viewer in ``folder``: a map with a vertex every 5 m of the small drive, a
    repeat drive of 60 frames under fog and night localized by two methods, camera images, and route following on
    one route from 100 m to 500 m: three episodes (night: one success, one off the road after 150 m; fog: one) with
    their traces (a row every 2.5 m of progress, 1 m east of the lane)."""
    graph, xy, _, _ = small_drive()
    graph.save_graphml(folder / "graph.graphml")
    teach = xy[::5]
    commands = np.where(np.arange(len(teach)) % 20 == 0, "turn_left", "follow")
    pd.DataFrame({"vertex": np.arange(len(teach)), "x": teach[:, 0], "y": teach[:, 1], "s": 5.0 * np.arange(len(teach)),
                  "gt_x": teach[:, 0], "gt_y": teach[:, 1], "command": commands}).to_csv(folder / "vertices.csv", index=False)
    repeat = xy[2::5][:60]
    rows = []
    for condition in ("fog", "night"):
        for method, shift in (("siamese network", 0), ("odometry only", 3)):
            for f, p in enumerate(repeat):
                vertex = min(f + shift, len(teach) - 1) if not (method == "odometry only" and f == 7) else -1
                rows.append({"condition": condition, "method": method, "frame": f, "gt_x": p[0], "gt_y": p[1],
                             "vertex": vertex, "s": 0.0, "error_m": float(np.hypot(*(teach[vertex] - p))) if vertex >= 0 else np.nan,
                             "event": "match", "score": 0.5})
    pd.DataFrame(rows).to_csv(folder / "frames.csv", index=False)
    images = np.random.default_rng(0).integers(0, 255, size=(2, len(repeat), 12, 40, 3), dtype=np.uint8)
    np.savez(folder / "places.npz", images=images, conditions=np.array(["fog", "night"]))
    progress = [400.0, 150.0, 20.0]
    pd.DataFrame({"episode": EPISODES, "route": 0, "route_start_m": 100.0, "route_length_m": 400.0,
                  "condition": ["night", "night", "fog"],
                  "agent": ["Topo-LP (ground truth)", "replay (place_loop)", "replay (place_loop)"],
                  "outcome": ["success", "off_road", "off_road"], "success": [True, False, False],
                  "progress_m": progress}).to_csv(folder / "episodes.csv", index=False)
    traces = []
    for key, agent, done in zip(EPISODES, ["Topo-LP (ground truth)", "replay (place_loop)", "replay (place_loop)"],
                                progress):
        s = np.append(np.arange(0.0, done, 2.5), done)
        k = np.minimum(np.round((100.0 + s) / 5).astype(int), len(teach) - 1)
        traces.append(pd.DataFrame({"episode": key, "route": 0, "condition": key.split("/")[1], "repeat": 0,
                                    "agent": agent, "localization": key.split("/")[-1], "step": 5 * np.arange(len(s)),
                                    "t_s": 0.5 * np.arange(len(s)), "s_m": s, "x": teach[k, 0] + 1.0, "y": teach[k, 1],
                                    "yaw": 0.0, "speed_mps": 5.0, "steer": 0.0, "vertex": k,
                                    "command": np.where(k % 20 == 0, "left", "follow"),
                                    "loc_x": teach[k, 0], "loc_y": teach[k, 1]}))
    pd.concat(traces).to_csv(folder / "traces.csv.gz", index=False)
    return {"graph": str(folder / "graph.graphml"), "vertices": str(folder / "vertices.csv"),
            "frames": str(folder / "frames.csv"), "repeat": str(folder / "places.npz"),
            "episodes": str(folder / "episodes.csv"), "traces": str(folder / "traces.csv.gz")}
