"""Evaluation from many starts: the per-start table of a short drive with known answers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from localization_helpers import corridor_graph

from topoloc.localization.evaluation import DriveTruth, Judge, score_start, start_frames, summarize


@pytest.fixture()
def corridor_drive():
    """The corridor 0-1-2-3 (edges 0, 1, 2; 100 m each) driven end to end, a frame per metre."""
    graph = corridor_graph()
    x = np.arange(0.0, 300.0)
    truth = DriveTruth(np.minimum(x // 100, 2).astype(np.int64), np.column_stack([x, np.zeros_like(x)]), x.copy())
    return graph, truth


def test_start_frames_every_100_m(corridor_drive):
    _, truth = corridor_drive
    assert start_frames(truth.driven, 100.0).tolist() == [0, 100, 200]
    assert start_frames(truth.driven, 120.0).tolist() == [0, 120, 240]


def test_judge_accepts_the_neighbouring_road_near_the_node_only(corridor_drive):
    graph, truth = corridor_drive
    judge = Judge(graph, 5.0)
    frames = np.array([50, 97, 103, 110])
    right = judge.right(np.array([1, 1, 0, 0]), truth.edge[frames], truth.xy[frames])
    assert right.tolist() == [False, True, True, False]  # 3 m from node 1 either road is fine, 10 m not
    assert not judge.right(np.array([3]), truth.edge[[97]], truth.xy[[97]])[0]  # a far road never is
    assert not Judge(graph, 0.0).right(np.array([1]), truth.edge[[97]], truth.xy[[97]])[0]


def test_judge_measures_from_the_true_junction_on_a_map_whose_node_moved(corridor_drive):
    graph, truth = corridor_drive
    moved = graph.nodes.copy()
    moved.loc[moved.index[1], "x"] += 6.0  # the map's node 1 lies 6 m past the junction the vehicle drives through
    frames = np.array([97, 103])
    answer = np.array([1, 0])  # the neighbouring road, 3 m from the true junction
    assert Judge(graph, 5.0).right(answer, truth.edge[frames], truth.xy[frames]).tolist() == [True, True]
    graph.nodes = moved
    assert Judge(graph, 5.0).right(answer, truth.edge[frames], truth.xy[frames]).tolist() == [False, True]  # 9 m, 3 m
    true_nodes = corridor_graph().nodes
    assert Judge(graph, 5.0, true_nodes).right(answer, truth.edge[frames], truth.xy[frames]).tolist() == [True, True]


def test_per_start_table(corridor_drive):
    graph, truth = corridor_drive
    judge = Judge(graph, 5.0)
    # an answer every 10 m; wrong (road 4, far away) until 150 m driven, right after; confident from 120 m on
    frames = np.arange(5, 300, 10)
    state = np.where(frames < 150, 4, truth.edge[frames])
    confidence = np.where(frames < 120, 0.2, 0.95)
    xy = truth.xy[frames] + [0.0, 2.0]
    rows = []
    for start in (0, 100, 200):
        keep = frames > start
        m = score_start(judge, truth, start, frames[keep], state[keep], confidence[keep], xy[keep], confirm_m=100.0, sure=0.9)
        rows.append({"drive": "d", "start": start, "localizer": "x", **m, "oracle_m": 50.0, "ratio": m["localized_m"] / 50.0})
    table = pd.DataFrame(rows)
    assert table.localized_m.tolist() == [150.0 - 5.0 + 10.0, 55.0, 5.0]  # first right answer at frame 155, 155, 205
    assert table.accuracy_after.tolist() == [1.0, 1.0, 1.0]
    assert table.position_error_m.tolist() == pytest.approx([2.0, 2.0, 2.0])
    assert table.confident_wrong.tolist() == pytest.approx([3 / 30, 3 / 20, 0.0])  # frames 125, 135, 145
    summary = summarize(table.assign(steps=[30.0, 20.0, 10.0]))
    row = summary[summary.drive == "all"].iloc[0]
    assert row.median_m == 55.0 and row.localized_share == 1.0 and row.median_ratio == pytest.approx(55.0 / 50.0)


def test_never_localized_counts_as_infinitely_far(corridor_drive):
    graph, truth = corridor_drive
    frames = np.arange(5, 300, 10)
    m = score_start(Judge(graph, 5.0), truth, 0, frames, np.full(len(frames), 4), np.full(len(frames), 0.99), None, 100.0, 0.9)
    assert np.isnan(m["localized_m"]) and m["confident_wrong"] == 1.0
    table = pd.DataFrame([{"drive": "d", "localizer": "x", **m, "oracle_m": 50.0, "ratio": np.inf}] * 2
                         + [{"drive": "d", "localizer": "x", **m, "localized_m": 40.0, "oracle_m": 50.0, "ratio": 0.8}])
    row = summarize(table).iloc[0]
    assert np.isnan(row.median_m) and row.localized_share == pytest.approx(1 / 3) and row.median_ratio == np.inf
