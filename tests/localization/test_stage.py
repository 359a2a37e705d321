"""The decode_trajectories stage rejects bad drives with one-line errors before loading a model."""

from __future__ import annotations

import pandas as pd
import pytest
from localization_helpers import irregular_grid

from topoloc.errors import InputError
from topoloc.localization.decode_trajectories import run

CONF = {"localization": {"max_offmap_m": 30.0, "rnn": {"window": 60, "stride": 20},
                         "decode": {"u_turns": "dead_ends", "max_skip_m": None}, "hmm": {"enabled": True}}, "drive": "d"}


@pytest.fixture()
def graph_file(tmp_path):
    graph, _ = irregular_grid()
    graph.save_graphml(tmp_path / "graph.graphml")
    return tmp_path / "graph.graphml"


def stage(tmp_path, graph_file, tokens: pd.DataFrame | str):
    path = tmp_path / "tokens.csv"
    if isinstance(tokens, str):
        path.write_text(tokens)
    else:
        tokens.to_csv(path, index=False)
    outputs = {k: str(tmp_path / f"out.{k}") for k in ("table", "stats", "geojson")}
    run(CONF, {"graph": str(graph_file), "tokens": str(path), "model": str(tmp_path / "none.ckpt")}, outputs)


def test_empty_trajectory(tmp_path, graph_file):
    with pytest.raises(InputError, match="empty trajectory: no tokens") as err:
        stage(tmp_path, graph_file, "index,token,segment,kind,frame,distance_m,edge_id,x,y\n")
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="empty trajectory"):
        stage(tmp_path, graph_file, "")


def test_drive_for_a_different_map(tmp_path, graph_file):
    tokens = pd.DataFrame({"token": [10] * 5, "edge_id": [0] * 5, "x": [5000.0 + 20 * i for i in range(5)], "y": [5000.0] * 5})
    with pytest.raises(InputError, match=r"the georeferenced track lies \d+ m \(median\) from the roads .*different map"):
        stage(tmp_path, graph_file, tokens)


def test_missing_model_after_checks(tmp_path, graph_file):
    tokens = pd.DataFrame({"token": [10] * 5, "edge_id": [0] * 5, "x": [20.0 * i for i in range(5)], "y": [0.0] * 5})
    with pytest.raises(InputError, match="model checkpoint not found"):
        stage(tmp_path, graph_file, tokens)
