"""Stage ``decode_trajectories``: the RNN's outputs on a test drive, decoded raw, by Strategy 1 and 2, and the HMM baseline.

Inputs: ``model`` (checkpoint of ``train_rnn``), ``graph``, ``tokens`` (``tokens.csv``
of ``segment_trajectory``: tokens with ground-truth edges). Outputs: ``table``
(per token: the truth and every decoder's online answer, decoded sequence and
confidence), ``stats`` (initial hypotheses, restarts, timings) and ``geojson``
(Strategy 1's edge sequence on the map, WGS84).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import write_json
from topoloc.localization.localize import DECODERS, Localizer, check_on_map, decoded_table, write_geojson, write_table
from topoloc.localization.rnn import load_model

log = logging.getLogger(__name__)


def read_tokens(path: str) -> pd.DataFrame:
    """A ``tokens.csv`` of ``segment_trajectory``; InputError if it is not one or holds no token."""
    try:
        tokens = pd.read_csv(path)
    except pd.errors.EmptyDataError:
        tokens = pd.DataFrame(columns=["token"])
    except (OSError, pd.errors.ParserError) as err:
        raise InputError(path, f"cannot read the tokens table ({err})") from err
    if "token" not in tokens.columns:
        raise InputError(path, "not a tokens table of segment_trajectory (no 'token' column)")
    if len(tokens) == 0:
        raise InputError(path, "empty trajectory: no tokens (the drive is shorter than one virtual-node spacing or does not move)")
    return tokens


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Decode drive ``conf['drive']``; write ``table``, ``stats`` and ``geojson``."""
    loc = conf["localization"]
    graph = RoadGraph.load(inputs["graph"])
    tokens = read_tokens(inputs["tokens"])
    if {"x", "y"} <= set(tokens.columns):
        check_on_map(graph, tokens[["x", "y"]].to_numpy(float), float(loc["max_offmap_m"]), inputs["tokens"], inputs["graph"])
    model = load_model(inputs["model"])
    localizer = Localizer(model, graph, loc, hmm=bool(loc["hmm"]["enabled"]))
    result = localizer.localize(tokens["token"].to_numpy(np.int64))
    table = decoded_table(tokens, result)
    write_table(outputs["table"], table)
    write_geojson(outputs["geojson"], graph, table, "strategy1")
    stats: dict[str, Any] = {
        "drive": conf.get("drive", ""),
        "tokens": len(tokens),
        "seconds": result.seconds,
        "setup_seconds": localizer.setup_s,
        "rnn_window": loc["rnn"].get("window"),
        "decoders": {
            name: {"initial_hypotheses": [int(e) for e in dec.initial], "restarts": int(dec.restarts),
                   "mean_hypotheses": float(np.mean(dec.hypotheses)) if len(dec.hypotheses) else 0.0, **dec.extra}
            for name, dec in result.decoded.items()
        },
    }
    if localizer.hmm is not None:
        stats["hmm_cells"] = localizer.hmm.num_cells
    write_json(outputs["stats"], stats)
    metrics: dict[str, float] = {"tokens": float(len(tokens))}
    metrics |= {f"seconds_{k}": v for k, v in result.seconds.items()}
    metrics["seconds_rnn_and_decoding"] = result.seconds["rnn"] + sum(result.seconds.get(n, 0.0) for n in ("raw", "strategy1", "strategy2"))
    if "true_edge_id" in table.columns:
        for name in result.decoded:
            if name in DECODERS:
                metrics[f"{name}_accuracy"] = float((table[f"{name}_online"] == table.true_edge_id).mean())
                metrics[f"{name}_path_accuracy"] = float((table[f"{name}_path"] == table.true_edge_id).mean())
    log.info("drive %s: %s", conf.get("drive", ""), metrics)
    return metrics
