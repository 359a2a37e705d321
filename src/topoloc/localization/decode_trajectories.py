"""Stage ``decode_trajectories``: every configured localizer on one drive, from a start every ``start_every_m``.

Inputs: ``graph``, ``poses`` (the drive's odometry, KITTI format, any frame: ``extract_odometry``),
``frames`` (its ``frames.csv``: the true road and position of every frame) and, when a learned localizer
is configured, ``model`` (the ``train_rnn`` checkpoint). Each localizer of ``localization.localizers``
(:func:`topoloc.registry.registry`) runs on the drive cut at every start frame
(:func:`topoloc.localization.evaluation.start_frames`), seeing nothing before it.

Outputs: ``answers`` (CSV, one row per start, localizer and update: the frame, the answer's road,
confidence and map position, the traced-back path, and the truth of that frame; then the top places of the
answer, ``place<i>_state``, ``_prob``, ``_x``, ``_y`` for i = 1 .. ``localization.places.top``: the first is the
answer itself, -1 / empty where there are fewer), ``stats`` (JSON: CPU seconds per localizer, starts, decoder
facts of the frame-0 run) and ``geojson`` (the frame-0 run of the first configured localizer that gives
positions, else the first one, in WGS84, with the top places of its last answer).
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json
from topoloc.localization.drive_on_map import write_geojson
from topoloc.localization.evaluation import DriveTruth, read_frames, start_frames
from topoloc.localization.roadmap import RoadMap
from topoloc.localizer import ROAD_OBSERVATIONS
from topoloc.motion.poses import Odometry
from topoloc.motion.poses import read_poses
from topoloc.registry import check_names, make, registry
from topoloc.trajectory.model import load_model

log = logging.getLogger(__name__)

ANSWER_COLUMNS = ["start", "localizer", "step", "frame", "state", "confidence", "x", "y", "path", "true_edge"]


def place_columns(top: int) -> list[str]:
    """The columns of the top places in ``answers.csv``, after :data:`ANSWER_COLUMNS`."""
    return [f"place{i}_{what}" for i in range(1, top + 1) for what in ("state", "prob", "x", "y")]


def road_conf(conf: dict[str, Any]) -> dict[str, Any]:
    """The slices a road localizer reads."""
    return {k: conf[k] for k in ("localization", "segmentation", "encoding")}


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Run every configured localizer on drive ``conf['drive']`` from every start; write the answers."""
    loc = conf["localization"]
    names = list(loc["localizers"])
    known = registry(ROAD_OBSERVATIONS)
    check_names(names, observes=ROAD_OBSERVATIONS)
    graph = RoadGraph.load(inputs["graph"])
    frames = read_frames(inputs["frames"])
    poses = read_poses(inputs["poses"])
    if len(poses) != len(frames):
        raise InputError(inputs["poses"], f"{len(poses)} poses for the {len(frames)} frames of {inputs['frames']}")
    truth = DriveTruth.from_frames(frames)
    odometry = Odometry.from_poses(poses)
    model = load_model(inputs["model"]) if any(known[name].requires_model for name in names) else None
    road = RoadMap(graph, loc["decode"]["u_turns"], loc["decode"]["max_skip_m"], model)
    starts = start_frames(truth.driven, float(loc["evaluate"]["start_every_m"]))
    lconf = road_conf(conf)
    top = int(loc["places"]["top"])
    tables, stats = [], {"drive": conf.get("drive", ""), "frames": len(frames), "starts": starts.tolist(), "localizers": {}}
    for name in names:
        localizer = make(name)
        began = time.process_time()
        runs = localizer.run_starts(odometry, road, lconf, starts)
        seconds = time.process_time() - began
        steps = sum(len(track) for _, _, track in runs)
        for start, observations, track in runs:
            tables.append(pd.DataFrame({
                "start": start, "localizer": name, "step": np.arange(len(track)), "frame": observations.frame,
                "state": track.state, "confidence": np.round(track.confidence, 5), "x": track.xy[:, 0], "y": track.xy[:, 1],
                "path": track.path, "true_edge": truth.edge[observations.frame],
                **{k: np.round(v, 5) if k.endswith("_prob") else v for k, v in track.place_columns(top).items()}}))
        facts = runs[0][2].extra.get("summary", {}) if runs and runs[0][0] == starts[0] else {}  # frame 0's facts
        stats["localizers"][name] = {"cpu_seconds": seconds, "updates": steps,
                                     "ms_per_update": 1000.0 * seconds / max(steps, 1), **facts}
        log.info("%s: %d starts, %d updates, %.2f s CPU", name, len(runs), steps, seconds)
    if not tables:
        raise InputError(inputs["poses"], "empty trajectory: the drive is too short to give any observation")
    answers = pd.concat(tables, ignore_index=True)[ANSWER_COLUMNS + place_columns(top)]
    with atomic_path(outputs["answers"]) as tmp:
        answers.to_csv(tmp, index=False, float_format="%.3f")
    first = answers[answers.start == starts[0]]
    shown = next((n for n in names if first[first.localizer == n].x.notna().any()), names[0])
    write_geojson(outputs["geojson"], graph, first[first.localizer == shown], shown, frames[["x", "y"]].to_numpy(float))
    write_json(outputs["stats"], stats)
    metrics = {f"{name}_cpu_seconds": s["cpu_seconds"] for name, s in stats["localizers"].items()}
    metrics |= {f"{name}_ms_per_update": s["ms_per_update"] for name, s in stats["localizers"].items()}
    metrics["starts"] = float(len(starts))
    return metrics
