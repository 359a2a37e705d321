"""Stage ``simulate_demonstrations``: the expert's noisy drives on training routes (see :mod:`topoloc.drive.demonstrations`).

Inputs: the region's OSM file (buildings) and road graph. Outputs: ``demonstrations`` (``.npz``), ``stats``
(counts, the expert's success rate, ``noise_injected_share``: the drive's own steps under noise injection,
``perturbed_share``: the steps off the expert's path, side views included, the closest step to the teach route) and
``sheet`` (sample steps of every condition).
"""

from __future__ import annotations

import logging
from typing import Any

from topoloc.drive.demonstrations import demonstrate
from topoloc.drive.plot import demonstrations_sheet
from topoloc.drive.routes import make_simulator, teach_route
from topoloc.drive.turn_routes import TrainingRoutes
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import write_json

log = logging.getLogger(__name__)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Record the demonstrations; write ``demonstrations``, ``stats`` and ``sheet``."""
    graph = RoadGraph.load(inputs["graph"])
    osm = inputs.get("osm")
    evaluation = teach_route(graph, conf)
    length = float(conf["drive"]["demonstrations"]["route_length_m"])
    demos, facts = demonstrate(osm, graph, conf, evaluation.xy,
                               TrainingRoutes(graph, conf, length),
                               lambda route: make_simulator(osm, graph, route, conf))
    demos.save(outputs["demonstrations"])
    write_json(outputs["stats"], facts)
    demonstrations_sheet(demos, outputs["sheet"])
    log.info("demonstrations: %s", facts)
    return facts
