"""Stage ``view_city``: the viewer of a city-scale map (experiment ``city``), ``.../experiments/city/viewer/<map>.html``.

Per map of ``experiments.city.maps`` (inputs ``osm_<map>``): the first drive of the experiment's first noise level
(the same draw as :mod:`topoloc.experiments.city`: seed ``[seed, map's place, 0]``, 3-10 km), the metric filter
live from its first frame (its answers and its belief: a heat layer that shrinks from the whole city to one road,
summed on a coarser grid while it is broad, see :mod:`topoloc.viewer.belief`), the true track, the starts every
``start_every_m`` and where the oracle finds the drive unique from the first start. Outputs: ``html_<map>``.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from topoloc.errors import InputError
from topoloc.graph.from_osm import build_road_graph
from topoloc.localization.evaluation import start_frames
from topoloc.localization.oracle import Oracle, true_path
from topoloc.localization.roadmap import RoadMap
from topoloc.odometry.simulate import NOISE_LEVELS, simulate_pattern_drive
from topoloc.viewer.drive_view import drive_data, truth_driven
from topoloc.viewer.page import write_viewer

log = logging.getLogger(__name__)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """One viewer per city map; their sizes (MB) and the metres until the metric filter was sure."""
    exp, ev = conf["city"], conf["localization"]["evaluate"]
    level = str(exp["levels"][0])
    metrics: dict[str, float] = {}
    for map_index, map_name in enumerate(exp["maps"]):
        osm = inputs.get(f"osm_{map_name}")
        if osm is None:
            raise InputError(f"experiments.city.osm.{map_name}", "no OSM file for this map")
        graph, _ = build_road_graph(str(osm), conf["graph"]["highway_classes"], float(conf["graph"]["virtual_node_spacing_m"]))
        rng = np.random.default_rng([int(exp["seed"]), map_index, 0])
        length = float(np.exp(rng.uniform(np.log(3000.0), np.log(10000.0))))
        sim = simulate_pattern_drive(graph, length, NOISE_LEVELS[level], rng, "random")
        driven = truth_driven(sim.gt_xy)
        starts = start_frames(driven, float(exp["start_every_m"]))
        road = RoadMap(graph, conf["localization"]["decode"]["u_turns"], conf["localization"]["decode"]["max_skip_m"])
        oracle = Oracle(graph, road.states, ev["oracle"]["angle_tol_deg"], ev["oracle"]["length_tol"])
        path = true_path(graph, sim.edge, sim.gt_xy, driven)
        oracle_m = oracle.count(path, int(starts[0]), float(ev["confirm_m"])).localized_m
        km = graph.edges.length_m.sum() / 1000.0
        data = drive_data(f"topoloc viewer: {map_name} ({km:.0f} km of road), a {sim.length_m / 1000:.1f} km drive, "
                          f"{level} noise", graph, sim.odometry, None, conf, sim.gt_xy, None, starts.tolist(),
                          None, road=road)
        if np.isfinite(oracle_m):
            frame = int(min(np.searchsorted(driven, driven[starts[0]] + oracle_m), len(driven) - 1))
            row = int(np.searchsorted(data.time["frame"], frame, side="right") - 1)
            lat, lon = data.truth[row]
            data.marks.append({"kind": "oracle", "name": "oracle", "idx": row, "lat": lat, "lon": lon,
                               "label": f"oracle: unique after {oracle_m:.0f} m"})
        data.fit_roads = True
        data.notes.append(f"{graph.num_edges} roads, {km:.0f} km; the belief is the metric filter's, summed on a grid "
                          "that is coarser while it is spread over the city.")
        size = write_viewer(outputs[f"html_{map_name}"], graph, data, conf["viewer"]["tiles"])
        sure = next((m for m in data.marks if m["kind"] == "sure"), None)
        metrics[f"{map_name}_size_mb"] = size / 2**20
        if sure is not None:
            metrics[f"{map_name}_sure_after_m"] = float(data.time["driven_m"][sure["idx"]])
        log.info("%s: %.0f km of road, a %.0f m drive, %d belief moments, %.2f MB", map_name, km, sim.length_m,
                 len(data.belief["idx"]) if data.belief else 0, size / 2**20)
    return metrics
