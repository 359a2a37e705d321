"""Stage ``view_drive``: the interactive viewer of one drive (``results/{region}/viewer/<drive>.html``).

Inputs: ``graph``, ``poses`` and ``frames`` (``extract_odometry``), ``answers`` and ``stats``
(``decode_trajectories``: the runs from the first start are shown; extra columns of the answers are ignored) and
``starts`` (``evaluate_localization``'s ``starts.csv``: where each localizer and the oracle became sure). The metric
filter's belief is computed here, from the first frame (see :mod:`topoloc.viewer.belief`). Output: ``html``.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.evaluation import read_frames
from topoloc.motion.poses import Odometry, read_poses
from topoloc.viewer.drive_view import check_answers, drive_data
from topoloc.viewer.page import write_viewer

log = logging.getLogger(__name__)


def localized_of(path: str, drive: str, start: int) -> dict[str, float]:
    """Per localizer (and ``oracle``), ``localized_m`` of the start ``start`` of ``drive`` in ``starts.csv``."""
    table = pd.read_csv(path)
    missing = {"drive", "start", "localizer", "localized_m"} - set(table.columns)
    if missing:
        raise InputError(path, f"not a starts table of evaluate_localization (no {sorted(missing)[0]!r} column)")
    rows = table[(table.drive.astype(str) == drive) & (table.start == start)]
    return {str(r.localizer): float(r.localized_m) for r in rows.itertuples()}


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Write the viewer of drive ``conf['drive']``; its size and the numbers of moments and localizers."""
    drive = str(conf["drive"])
    graph = RoadGraph.load(inputs["graph"])
    frames = read_frames(inputs["frames"])
    poses = read_poses(inputs["poses"])
    if len(poses) != len(frames):
        raise InputError(inputs["poses"], f"{len(poses)} poses for the {len(frames)} frames of {inputs['frames']}")
    stats = json.loads(Path(inputs["stats"]).read_text())
    starts = [int(s) for s in stats.get("starts", [0])]
    answers = check_answers(pd.read_csv(inputs["answers"]), inputs["answers"])
    if "start" in answers.columns:
        answers = answers[answers.start == starts[0]]
    truth = frames[["gt_x", "gt_y"]].to_numpy(float) if {"gt_x", "gt_y"} <= set(frames.columns) else None
    if truth is not None and not np.isfinite(truth).all():
        truth = None
    localized = localized_of(inputs["starts"], drive, starts[0]) if inputs.get("starts") else None
    title = f"topoloc viewer: {conf['region']} drive {drive}"
    data = drive_data(title, graph, Odometry.from_poses(poses), answers, conf, truth,
                      frames["time_s"].to_numpy(float) if "time_s" in frames.columns else None, starts, localized)
    size = write_viewer(outputs["html"], graph, data, conf["viewer"]["tiles"])
    moments = len(data.belief["idx"]) if data.belief else 0
    log.info("%s: %d localizers, %d belief moments, %.2f MB", outputs["html"], len(data.agents), moments, size / 2**20)
    return {"size_mb": size / 2**20, "belief_moments": float(moments), "localizers": float(len(data.agents))}
