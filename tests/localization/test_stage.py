"""The decode_trajectories stage: every configured localizer from every start; one-line errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from localization_helpers import irregular_grid

from topoloc.config import load
from topoloc.errors import InputError
from topoloc.localization.decode_trajectories import run
from topoloc.motion.poses import poses_from_planar, write_poses

ROUTE = [0, 1, 6, 7, 8, 13, 14, 9, 4]


def conf(localizers=("hmm", "metric")):
    full = load(None)
    full["localization"]["localizers"] = list(localizers)
    full["localization"]["evaluate"]["start_every_m"] = 300.0
    return {k: full[k] for k in ("localization", "segmentation", "encoding")} | {"drive": "d"}


@pytest.fixture()
def drive(tmp_path):
    """The grid map, and a drive along ROUTE (a point every metre, heading of travel) with its frames table."""
    graph, edges = irregular_grid()
    graph.save_graphml(tmp_path / "graph.graphml")
    index = {frozenset(e): k for k, e in enumerate(edges)}
    xy, labels = [], []
    for a, b in zip(ROUTE[:-1], ROUTE[1:]):
        p, q = graph.nodes.loc[a, ["x", "y"]].to_numpy(float), graph.nodes.loc[b, ["x", "y"]].to_numpy(float)
        n = int(np.hypot(*(q - p)))
        xy.append(p + (q - p) * np.arange(n)[:, None] / n)
        labels += [index[frozenset((a, b))]] * n
    xy = np.vstack(xy)
    step = np.diff(xy, axis=0, append=xy[-1:] + (xy[-1:] - xy[-2:-1]))
    write_poses(tmp_path / "poses.txt", poses_from_planar(xy - xy[0], np.arctan2(step[:, 1], step[:, 0])))
    frames = pd.DataFrame({"frame": np.arange(len(xy)), "x": xy[:, 0], "y": xy[:, 1], "gt_x": xy[:, 0], "gt_y": xy[:, 1],
                           "edge_id": labels})
    frames.to_csv(tmp_path / "frames.csv", index=False)
    return tmp_path


def outputs(tmp_path):
    return {"answers": str(tmp_path / "answers.csv"), "stats": str(tmp_path / "decoded.json"),
            "geojson": str(tmp_path / "loc.geojson")}


def inputs(tmp_path, **extra):
    return {"graph": str(tmp_path / "graph.graphml"), "poses": str(tmp_path / "poses.txt"),
            "frames": str(tmp_path / "frames.csv"), **extra}


def test_every_localizer_from_every_start(drive):
    run(conf(), inputs(drive), outputs(drive))
    answers = pd.read_csv(drive / "answers.csv")
    stats = json.loads((drive / "decoded.json").read_text())
    assert stats["starts"] == [0, 300, 600]  # a start every 300 m of the 794 m drive
    assert set(answers.localizer) == {"hmm", "metric"} and set(answers.start) == {0, 300, 600}
    for (start, name), run_ in answers.groupby(["start", "localizer"]):
        assert run_.frame.min() > start and run_.frame.is_monotonic_increasing
        assert (run_.true_edge.to_numpy() == pd.read_csv(drive / "frames.csv").edge_id.to_numpy()[run_.frame]).all()
    metric = answers[(answers.localizer == "metric") & (answers.start == 0)]
    assert metric.x.notna().all() and (metric.state.iloc[-20:] == metric.true_edge.iloc[-20:]).mean() > 0.8
    assert stats["localizers"]["hmm"]["initial_hypotheses"] and stats["localizers"]["metric"]["updates"] > 300
    geo = json.loads((drive / "loc.geojson").read_text())
    assert {f["properties"]["kind"] for f in geo["features"]} >= {"decoded_edge", "positions", "track"}


def test_unknown_localizer_is_one_line(drive):
    with pytest.raises(InputError, match=r"^localization.localizers.1: unknown localizer 'kalman'; choose from \[") as err:
        run(conf(("metric", "kalman")), inputs(drive), outputs(drive))
    assert "\n" not in str(err.value)


def test_empty_or_mismatched_drive(drive, tmp_path):
    frames = pd.read_csv(drive / "frames.csv")
    frames.iloc[:1].to_csv(tmp_path / "one.csv", index=False)
    with pytest.raises(InputError, match="empty trajectory: a drive needs at least two frames"):
        run(conf(), inputs(drive, frames=str(tmp_path / "one.csv")), outputs(tmp_path))
    frames.iloc[:100].to_csv(tmp_path / "short.csv", index=False)
    with pytest.raises(InputError, match=r"poses.txt: \d+ poses for the 100 frames of"):
        run(conf(), inputs(drive, frames=str(tmp_path / "short.csv")), outputs(tmp_path))
    assert not (tmp_path / "answers.csv").exists()


def test_learned_localizer_needs_its_model(drive):
    with pytest.raises(InputError, match="model checkpoint not found"):
        run(conf(("strategy1",)), inputs(drive, model=str(drive / "none.ckpt")), outputs(drive))
