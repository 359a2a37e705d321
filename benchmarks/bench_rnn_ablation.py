"""Ablation of the trajectory RNN: cell, size and inputs, judged on held-out simulated drives and on KITTI 00.

Needs the kitti00 pipeline's dataset, graph and odometry (``snakemake results/kitti00/dataset/stats.json
results/kitti00/segments/gt/tokens.csv results/kitti00/segments/orbslam2/tokens.csv --configfile
config/regions/kitti00.yaml``)::

    PYTHONPATH=src python benchmarks/bench_rnn_ablation.py [--configfile config/regions/kitti00.yaml]
        [--variants lstm-128,gru-128,rnn-128,lstm-64,lstm-256,lstm-128-tokens] [--localizers rnn_filter,strategy1]
        [--out results/bench_rnn_ablation]

A variant is ``CELL-HIDDEN`` (the dataset's continuous features beside the angle token) or
``CELL-HIDDEN-tokens`` (the angle token alone: the paper's input, same paths and labels). Each is trained with
the config's ``train`` section (epochs from the config, so the figures do not depend on the machine's load)
and judged by: training wall time; held-out accuracy over all steps and at 200 / 500 / 1000 m driven (Fig. 8);
and, from a start every ``localization.evaluate.start_every_m`` of the real KITTI 00 drives (``gt``,
``orbslam2``), each localizer's share of starts localized, median distance to localized and accuracy after,
beside the token HMM and the oracle. Rows go to ``--out``/ablation.csv as each variant ends (a stopped run keeps
the finished ones; a rerun skips variants already there), the checkpoints to ``--out``/<variant>.ckpt.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from bench_localization import evaluate_kitti

from topoloc.config import dotted_overrides, load
from topoloc.trajectory.dataset import load_features, load_sequences
from topoloc.trajectory.evaluate_rnn import accuracy_by_distance, driven_metres
from topoloc.trajectory.model import predict
from topoloc.trajectory.train_rnn import fit

REPO = Path(__file__).resolve().parents[1]
DEFAULT_VARIANTS = "lstm-128,gru-128,rnn-128,lstm-64,lstm-256,lstm-128-tokens"
AT_METRES = (200, 500, 1000)


def parse_variant(name: str) -> tuple[str, int, bool]:
    """``lstm-128`` -> ("lstm", 128, True); ``gru-64-tokens`` -> ("gru", 64, False)."""
    parts = name.split("-")
    if len(parts) not in (2, 3) or not parts[1].isdigit() or (len(parts) == 3 and parts[2] != "tokens"):
        raise SystemExit(f"bench_rnn_ablation: variant {name!r} is not CELL-HIDDEN or CELL-HIDDEN-tokens")
    return parts[0], int(parts[1]), len(parts) == 2


def held_out(model, data: Path, feature_dim: int, spacing_m: float) -> dict[str, float]:
    """Accuracy over every held-out step, and in the 100 m bins that end at 200, 500 and 1000 m driven."""
    tokens, labels = load_sequences(data / "val.parquet")
    features = load_features(data / "val.parquet", feature_dim) if feature_dim else None
    model_dim = int(model.hparams.get("feature_dim", 0))
    pred = predict(model, tokens, inputs=features if model_dim else None)
    row = {"heldout_acc": float(np.mean(np.concatenate([p == y for p, y in zip(pred, labels)])))}
    if features is not None:
        table = accuracy_by_distance(pred, labels, driven_metres(features, spacing_m)).set_index("metres")
        for m in AT_METRES:
            row[f"heldout_acc_{m}m"] = float(table.accuracy.get(float(m), np.nan))
    return row


def drive_figures(summary: pd.DataFrame, localizer: str) -> dict[str, float]:
    """``<drive>_localized_share``, ``<drive>_median_m``, ``<drive>_accuracy_after`` of one localizer."""
    s = summary.set_index(["drive", "localizer"])
    return {f"{d}_{k}": float(s.loc[(d, localizer), k]) for d in ("gt", "orbslam2")
            for k in ("localized_share", "median_m", "accuracy_after")}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--configfile", default=str(REPO / "config" / "regions" / "kitti00.yaml"))
    parser.add_argument("--results", default=None, help="results folder of the region (default: results/<region.name>)")
    parser.add_argument("--variants", default=DEFAULT_VARIANTS)
    parser.add_argument("--localizers", default="rnn_filter,strategy1")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="override config keys")
    parser.add_argument("--out", default="results/bench_rnn_ablation")
    args = parser.parse_args(argv)
    conf = load(args.configfile, dotted_overrides(args.set))
    results = Path(args.results or Path("results") / conf["region"]["name"])
    data = results / "dataset"
    stats = json.loads((data / "stats.json").read_text())
    spacing = json.loads((results / "graph" / "stats.json").read_text())["virtual_node_spacing_m"]
    dataset_dim = int(stats.get("feature_dim", 0))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table_path = out / "ablation.csv"
    done = pd.read_csv(table_path) if table_path.is_file() else pd.DataFrame()
    localizers = args.localizers.split(",")

    if done.empty or "hmm" not in set(done.get("variant", [])):
        _, summary, _, _ = evaluate_kitti(results, conf, ["hmm"])
        rows = [{"variant": name, "localizer": name, **drive_figures(summary, name)} for name in ("hmm", "oracle")]
        done = pd.concat([done, pd.DataFrame(rows)], ignore_index=True)
        done.to_csv(table_path, index=False)

    for variant in args.variants.split(","):
        if variant in set(done.variant):
            continue
        cell, hidden, with_features = parse_variant(variant)
        vconf = {"encoding": conf["encoding"], "train": conf["train"],
                 "model": {**conf["model"], "cell": cell, "hidden_size": hidden}}
        dim = dataset_dim if with_features else 0
        if with_features and not dataset_dim:
            raise SystemExit(f"bench_rnn_ablation: {data}/stats.json has no features (dataset.simulated.features)")
        ckpt = out / f"{variant}.ckpt"
        print(f"{variant}: training", file=sys.stderr, flush=True)
        began = time.perf_counter()
        model, _, metrics = fit(vconf, str(data / "train.parquet"), str(data / "val.parquet"), int(stats["classes"]),
                                str(ckpt), feature_dim=dim)
        row = {"variant": variant, "train_s": time.perf_counter() - began, "epochs": metrics["epochs"],
               "parameters": sum(p.numel() for p in model.parameters()), **held_out(model, data, dataset_dim, spacing)}
        print(f"{variant}: localizing from many starts", file=sys.stderr, flush=True)
        _, summary, _, _ = evaluate_kitti(results, conf, localizers, ckpt)
        rows = [{**row, "localizer": name, **drive_figures(summary, name)} for name in localizers]
        done = pd.concat([done, pd.DataFrame(rows)], ignore_index=True)
        done.to_csv(table_path, index=False)
        print(done.to_markdown(index=False, floatfmt=".3f"), flush=True)
    print(f"\n## Trajectory RNN ablation on {conf['region']['name']} (rows: {table_path})\n")
    print(done.to_markdown(index=False, floatfmt=".3f"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
