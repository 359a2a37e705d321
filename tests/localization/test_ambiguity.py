"""Ambiguity in the answer: a drive that two places explain equally (a mirror walk on a dual carriageway) ends
unsure, with both places among the answer's top places; the places' columns in answers.csv and the GeoJSON."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from localization_helpers import drive_along, dual_carriageway

from topoloc.config import load
from topoloc.localization.drive_on_map import write_geojson
from topoloc.localization.roadmap import RoadMap
from topoloc.localizer import Answer, Place, Track, merge_places
from topoloc.motion.poses import Odometry
from topoloc.registry import make

@pytest.fixture(scope="module")
def mirror():
    """The mirror map and an out-and-back: 350 m east on edge 0 from x = 50, the east U-turn, 300 m west on edge 3
    (ending at x = 100); the odometry in a frame turned by 40 degrees and shifted (the filters never see the map's)."""
    graph, _, _ = dual_carriageway(400.0, round_ends=True)
    xy, yaw, edge, _ = drive_along(graph, [0, 1, 4, 2, 3], start_m=50.0)
    end = np.flatnonzero((edge == 3) & (xy[:, 0] <= 100.0))[0]
    xy, yaw, edge = xy[:end + 1], yaw[:end + 1], edge[:end + 1]
    turn = np.radians(40.0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    odometry = Odometry((xy - xy[0]) @ rot.T + [12.0, -3.0], yaw + turn)
    conf = {k: load(None)[k] for k in ("localization", "segmentation", "encoding")}
    return graph, RoadMap(graph), conf, odometry, xy, edge


@pytest.mark.parametrize("name", ["metric", "hmm"])
def test_a_mirror_drive_ends_unsure_with_both_places(mirror, name):
    graph, road, conf, odometry, xy, edge = mirror
    localizer = make(name)
    observations = localizer.observe(odometry, road, conf)
    localizer.reset(road, conf)
    track = localizer.run(observations.items)
    sure = conf["localization"]["evaluate"]["sure"]
    assert track.confidence[-1] < sure and track.confidence[-1] <= 0.55, track.confidence[-10:]
    places = track.places[-1]
    assert track.state[-1] == places[0].state and track.confidence[-1] == pytest.approx(places[0].probability)
    by_road = {p.state: p for p in places}
    assert {0, 3} <= set(by_road), places  # the true carriageway (3) and its mirror (0)
    assert min(by_road[0].probability, by_road[3].probability) >= 0.35, places
    # the positions: the truth at the last observation on the west road, and its mirror image (a half turn about the
    # map's centre) on the east road
    truth = xy[observations.frame[-1]]
    centre = graph.nodes.loc[[0, 1, 2, 3], ["x", "y"]].to_numpy(float).mean(axis=0)
    assert np.hypot(*(np.asarray(by_road[3].xy) - truth)) < 12.0
    assert np.hypot(*(np.asarray(by_road[0].xy) - (2 * centre - truth))) < 12.0
    # out on the first road, before the U-turn tells anything, it is never sure either
    assert (track.confidence < sure).all()


def test_the_places_columns_and_the_geojson(mirror, tmp_path):
    graph, road, conf, odometry, _, _ = mirror
    localizer = make("metric")
    observations = localizer.observe(odometry, road, conf)
    localizer.reset(road, conf)
    track = localizer.run(observations.items)
    cols = track.place_columns(3)
    assert list(cols) == [f"place{i}_{w}" for i in (1, 2, 3) for w in ("state", "prob", "x", "y")]
    assert (cols["place1_state"] == track.state).all() and np.allclose(cols["place1_prob"], track.confidence)
    ranked = np.column_stack([np.nan_to_num(cols[f"place{i}_prob"]) for i in (1, 2, 3)])
    assert (np.diff(ranked, axis=1) <= 1e-9).all() and (ranked.sum(axis=1) <= 1.0 + 1e-5).all()
    answers = pd.DataFrame({"frame": observations.frame, "path": track.path, "confidence": track.confidence,
                            "x": track.xy[:, 0], "y": track.xy[:, 1], **cols})
    write_geojson(tmp_path / "loc.geojson", graph, answers, "metric")
    places = [f["properties"] for f in json.loads((tmp_path / "loc.geojson").read_text())["features"]
              if f["properties"]["kind"] == "place"]
    assert [p["rank"] for p in places][:2] == [1, 2] and {p["edge_id"] for p in places} >= {0, 3}
    assert places[0]["probability"] == pytest.approx(track.confidence[-1], abs=1e-4)


def test_merge_places_adds_up_places_within_merge_m():
    xy = np.array([[0.0, 0.0], [3.0, 0.0], [100.0, 0.0], [0.0, 4.0], [np.nan, np.nan]])
    places = merge_places([7, 8, 9, 10, 11], [0.3, 0.25, 0.35, 0.05, 0.05], xy, k=3, merge_m=5.0)
    assert places == [Place(7, pytest.approx(0.6), (0.0, 0.0)), Place(9, 0.35, (100.0, 0.0)), Place(11, 0.05, None)]
    unmerged = merge_places([7, 8, 9, 10, 11], [0.3, 0.25, 0.35, 0.05, 0.05], xy, k=2, merge_m=0.0)
    assert [p.state for p in unmerged] == [9, 7]
    assert merge_places([1], [0.0], None, k=3) == []
    # a localizer without places: the answer itself is its one place, none without an answer
    track = Track.of_answers([Answer(4, 0.7, (1.0, 2.0)), Answer(-1, 0.0)])
    cols = track.place_columns(2)
    assert cols["place1_state"].tolist() == [4, -1] and cols["place1_prob"][0] == 0.7 and cols["place1_y"][0] == 2.0
    assert cols["place2_state"].tolist() == [-1, -1] and np.isnan(cols["place2_prob"]).all()


def test_the_metric_filters_recalibration_changes_the_confidences_only(mirror):
    """``confidence_scale`` and ``confidence_shift`` map every place's probability, the answer's confidence with it,
    through :class:`~topoloc.localization.calibration.LogitCalibration`; the answers and the places' order stay."""
    from topoloc.localization.calibration import LogitCalibration

    _, road, conf, odometry, _, _ = mirror
    cooled = {**conf, "localization": {**conf["localization"], "metric": {
        **conf["localization"]["metric"], "confidence_scale": 0.6, "confidence_shift": -0.3}}}
    calibrate = LogitCalibration(0.6, -0.3)
    starts = np.array([0, 200])
    tracks = {}
    for label, c in (("raw", conf), ("cooled", cooled)):
        localizer = make("metric")
        observations = localizer.observe(odometry, road, c)
        localizer.reset(road, c)
        tracks[label] = [localizer.run(observations.items)] + [t for _, _, t in localizer.run_starts(odometry, road, c, starts)]
    for raw, cooled_track in zip(tracks["raw"], tracks["cooled"]):
        assert np.array_equal(raw.state, cooled_track.state)
        assert np.allclose(cooled_track.confidence, calibrate.array(raw.confidence))
        assert (cooled_track.confidence[raw.confidence > 0.5] < raw.confidence[raw.confidence > 0.5]).all()
        for before, after in zip(raw.places, cooled_track.places):
            assert [p.state for p in before] == [p.state for p in after]
            assert [p.probability for p in after] == pytest.approx([calibrate(p.probability) for p in before])
