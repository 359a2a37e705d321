"""The city viewer (rule view_city) on the central-Helsinki extract standing in for a city map: the experiment's first
drive, the metric filter's answers and a belief whose heat layer shrinks from the map to one road."""

from __future__ import annotations

import numpy as np
import pytest
from viewer_helpers import embedded

from topoloc.config import load
from topoloc.viewer.view_city import run

pytestmark = pytest.mark.slow


def test_the_city_viewer_shrinks_the_belief_to_one_road(helsinki_pbf, tmp_path):
    conf = load(None, {"viewer": {"belief_every_m": 50.0}})
    city = {**conf["experiments"]["city"], "maps": ["helsinki"], "osm": {"helsinki": str(helsinki_pbf)}}
    sliced = {k: conf[k] for k in ("localization", "segmentation", "encoding", "graph", "viewer")} | {"city": city}
    out = tmp_path / "helsinki.html"
    metrics = run(sliced, {"osm_helsinki": str(helsinki_pbf)}, {"html_helsinki": str(out)})
    blob = embedded(out)
    assert metrics["helsinki_size_mb"] == pytest.approx(out.stat().st_size / 2**20)
    assert [a["name"] for a in blob["agents"]] == ["metric"] and blob["fit_roads"]
    assert 500 < blob["time"]["driven_m"][-1] <= 10100  # the experiment's drives: up to 10 km (shorter on this small map)
    heat = blob["belief"]["heat"]
    first_spread = np.ptp(np.array(heat[0])[:, :2], axis=0).max()  # degrees the first heat layer spans
    assert len(heat[0]) > 20 and first_spread > 0.005
    last_spread = np.ptp(np.array(heat[-1])[:, :2], axis=0).max()
    assert last_spread < first_spread / 10 and blob["belief"]["roads"][-1][0][1] > 0.9  # one road at the end
    assert [m["kind"] for m in blob["marks"]].count("oracle") == 1
    assert "helsinki_sure_after_m" in metrics and metrics["helsinki_sure_after_m"] < blob["time"]["driven_m"][-1]
