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

from localization_helpers import irregular_grid

from topoloc.config import load
from topoloc.localization.roadmap import RoadMap
from topoloc.motion.poses import Odometry, poses_from_planar
from topoloc.registry import make
from topoloc.viewer.drive_view import drive_data
from topoloc.viewer.page import write_viewer

ROUTE = [0, 1, 6, 7, 8, 13, 14, 9, 4]
OFFSET = np.array([385000.0, 6670000.0])  # the grid placed in Helsinki, EPSG:3067


def route_track(graph, nodes, step=1.0):
    """Points every ``step`` metres along the straight roads between ``nodes``."""
    pts = []
    for a, b in zip(nodes[:-1], nodes[1:]):
        p, q = graph.nodes.loc[a, ["x", "y"]].to_numpy(float), graph.nodes.loc[b, ["x", "y"]].to_numpy(float)
        n = int(np.hypot(*(q - p)) / step)
        pts.append(p + (q - p) * np.arange(n)[:, None] / n)
    pts.append(graph.nodes.loc[[nodes[-1]], ["x", "y"]].to_numpy(float))
    return np.vstack(pts)


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
