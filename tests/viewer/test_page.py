"""The viewer's file without a browser: offline (Leaflet inlined, no CDN), its data, the decimated belief."""

from __future__ import annotations

import re

import numpy as np
import pytest
from viewer_helpers import embedded

from topoloc.errors import InputError
from topoloc.viewer.belief import heat_points
from topoloc.viewer.page import ViewerData, render_html, rows_of, thin_rows


def test_heat_points_coarsen_until_few_and_keep_the_mass_centre():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 5000, size=(20000, 2))
    weight = rng.uniform(size=len(xy))
    identity = lambda p: np.round(np.asarray(p), 6).tolist()  # noqa: E731 (map coordinates as "lat, lon")
    points = heat_points(xy, weight, 1.0, 64, identity)
    assert 4 <= len(points) <= 64
    assert max(p[2] for p in points) == 1.0
    # one sharp peak: one point, at the weighted centre of its cells
    peak = heat_points(np.array([[10.0, 10.0], [10.5, 10.0], [900.0, 900.0]]), np.array([1.0, 3.0, 1e-9]), 1.0, 64, identity)
    assert len(peak) == 1 and peak[0][:2] == pytest.approx([10.375, 10.0]) and peak[0][2] == 1.0
    assert heat_points(xy[:0], weight[:0], 1.0, 64, identity) == []


def test_thin_rows_and_rows_of():
    assert thin_rows(5, 10).tolist() == [0, 1, 2, 3, 4]
    rows = thin_rows(1001, 11)
    assert rows.tolist() == list(range(0, 1001, 100))
    assert rows_of([0, 99, 100, 250, 5000], rows).tolist() == [0, 0, 1, 2, 10]


def test_the_file_is_offline_and_holds_every_localizer(small_viewer):
    path, data, graph, xy = small_viewer
    html = path.read_text(encoding="utf-8")
    assert not re.search(r"<script[^>]*\bsrc=", html) and not re.search(r"<link[^>]*\bhref=", html)
    assert "Leaflet 1.9.4" in html and "L.heatLayer" in html and "topolocViewer" in html
    blob = embedded(path)
    assert [a["name"] for a in blob["agents"]] == ["metric", "hmm"]
    assert len(blob["truth"]) == len(blob["time"]["frame"]) == len(xy)
    assert blob["time"]["driven_m"][-1] == pytest.approx(np.hypot(*np.diff(xy, axis=0).T).sum(), abs=0.1)
    metric = blob["agents"][0]
    assert len(metric["idx"]) == len(metric["edge"]) == len(metric["conf"]) == len(metric["pos"]) > 300
    assert all(abs(lat - 60.152) < 0.01 and abs(lon - 24.93) < 0.02 for lat, lon in (p for p in metric["pos"] if p))
    kinds = [m["kind"] for m in blob["marks"]]
    assert kinds.count("start") == 2 and kinds.count("sure") == 2 and kinds.count("oracle") == 1
    sure = next(m for m in blob["marks"] if m["name"] == "metric")
    assert blob["time"]["driven_m"][sure["idx"]] == pytest.approx(150.0, abs=1.5)
    assert len(blob["roads"]) > 3 and blob["map"].startswith("map_")


def test_the_belief_shrinks_onto_the_true_road(small_viewer):
    path, data, graph, xy = small_viewer
    belief = embedded(path)["belief"]
    assert len(belief["idx"]) == len(belief["roads"]) == len(belief["heat"]) >= 40  # a moment every 10 m of 800 m
    assert all(len(r) <= 10 and len(h) <= 50 for r, h in zip(belief["roads"], belief["heat"]))
    first, final = belief["roads"][0], belief["roads"][-1]
    assert len(first) > 3 and first[0][1] < 0.5  # spread at the start
    end_edge = data.agents[0]["edge"][-1]
    assert final[0][1] > 0.9 and final[0][0] == end_edge  # one road at the end: the metric filter's answer
    assert len(belief["heat"][-1]) < len(belief["heat"][0])
    assert set(belief["names"]) >= {str(e) for e, _ in final}


def test_nothing_to_draw_is_a_clear_error():
    with pytest.raises(InputError, match="nothing to draw"):
        render_html(None, ViewerData(title="empty", time={"frame": [0], "driven_m": [0.0], "t_s": [0.0]}))


def test_the_assets_digest_follows_the_assets(tmp_path, monkeypatch):
    import shutil

    import topoloc.viewer.page as page

    copy = tmp_path / "assets"
    shutil.copytree(page.ASSETS, copy)
    monkeypatch.setattr(page, "ASSETS", copy)
    before = page.assets_digest()
    assert before == page.assets_digest() and len(before) == 64
    (copy / "viewer.js").write_text((copy / "viewer.js").read_text() + "\n// edited\n")
    assert page.assets_digest() != before
