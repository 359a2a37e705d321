"""Stage ``build_topometric_map``: the teach drive's topometric map (see :mod:`topoloc.place.topometric_map`).

Outputs: ``map`` (the vertices as ``.npz``: embeddings, baseline descriptors, path-integrated positions,
commands, ground truth), ``vertices`` (a CSV of positions, arc lengths and commands), ``stats`` (counts,
path-integration drift, embedding speed, the intersections passed) and ``figure``.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import pandas as pd
import torch

from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json
from topoloc.place.images import PlaceSet
from topoloc.place.network import load_model
from topoloc.place.plot import map_figure
from topoloc.place.topometric_map import COMMANDS, build_map

log = logging.getLogger(__name__)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Build the map from ``inputs`` model / teach / graph; write ``map``, ``vertices``, ``stats`` and ``figure``."""
    torch.set_num_threads(int(conf["threads"]))
    model = load_model(inputs["model"])
    teach = PlaceSet.load(inputs["teach"])
    graph = RoadGraph.load(inputs["graph"])
    topo, crossings, facts = build_map(teach, graph, model, conf)
    topo.save(outputs["map"])
    table = pd.DataFrame({"vertex": np.arange(len(topo)), "x": topo.xy[:, 0], "y": topo.xy[:, 1], "s": topo.s,
                          "gt_x": topo.gt_xy[:, 0], "gt_y": topo.gt_xy[:, 1],
                          "command": [COMMANDS[c] for c in topo.command]})
    with atomic_path(outputs["vertices"]) as tmp:
        table.to_csv(tmp, index=False, float_format="%.3f")
    write_json(outputs["stats"], {**facts, "condition": topo.condition,
                                  "crossings": [vars(c) for c in crossings]})
    map_figure(topo, crossings, outputs["figure"])
    log.info("map: %s", facts)
    return facts
