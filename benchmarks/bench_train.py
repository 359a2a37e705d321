"""Training benchmark: held-out last-position accuracy of the trajectory RNN against wall time.

Usage (after `snakemake all` built the dataset of the config)::

    python -m benchmarks.bench_train [--configfile config/config.yaml] [--region helsinki]
        [--set train.max_epochs=20 model.cell=gru ...]

Trains with the config's ``model`` and ``train`` sections (as the ``train_rnn`` stage does, without
MLflow) on ``results/{region}/dataset``, then prints the wall time, epochs, the last-position accuracy
on training and held-out trajectories (the paper's Eq. 6) and the ceiling of any causal model. The
issue's target: >= 0.95 held-out last-position accuracy within 5 minutes on a 2-core CPU.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

from benchmarks.markdown import add_out_option, markdown_copy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--configfile", default="config/config.yaml")
    parser.add_argument("--region", default=None, help="results/{region}/dataset (default: region.name of the config)")
    parser.add_argument("--save", default=None, help="also keep the trained checkpoint here")
    parser.add_argument("--data", default=None, help="dataset folder (default: results/{region}/dataset)")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="override config keys")
    add_out_option(parser, "bench_train")
    args = parser.parse_args()
    with markdown_copy(args.out):
        import numpy as np
        import torch

        from topoloc.config import dotted_overrides, load
        from topoloc.trajectory.dataset import load_features, load_sequences
        from topoloc.trajectory.accuracy import accuracy_by_position, prefix_majority
        from topoloc.trajectory.model import predict
        from topoloc.trajectory.fitting import fit

        config = load(args.configfile, dotted_overrides(args.set))
        region = args.region or config["region"]["name"]
        data = Path(args.data) if args.data else Path("results") / region / "dataset"
        stats = json.loads((data / "stats.json").read_text())
        conf = {"encoding": config["encoding"], "model": config["model"], "train": config["train"]}

        with tempfile.TemporaryDirectory() as tmp:
            started = time.perf_counter()
            model, history, metrics = fit(conf, str(data / "train.parquet"), str(data / "val.parquet"), int(stats["classes"]),
                                          f"{tmp}/model.ckpt", feature_dim=int(stats.get("feature_dim", 0)))
            wall = time.perf_counter() - started
            if args.save:
                shutil.copyfile(f"{tmp}/model.ckpt", args.save)
        train_tokens, train_labels = load_sequences(data / "train.parquet")
        val_tokens, val_labels = load_sequences(data / "val.parquet")
        everything = (train_tokens + val_tokens, train_labels + val_labels)
        dim = int(stats.get("feature_dim", 0))
        rows = {}
        for split in ("train", "held-out"):
            path = data / ("train.parquet" if split == "train" else "val.parquet")
            tokens, labels = (train_tokens, train_labels) if split == "train" else (val_tokens, val_labels)
            pred = predict(model, tokens, inputs=load_features(path, dim) if dim else None)
            last = accuracy_by_position(pred, labels).set_index("position").loc["last", "accuracy"]
            ceiling = accuracy_by_position(prefix_majority(*everything, tokens), labels).set_index("position").loc["last", "accuracy"]
            every = float(np.mean(np.concatenate([p == y for p, y in zip(pred, labels)])))
            rows[split] = (last, ceiling, every)
        print(f"region {region}: cell {conf['model']['cell']}, {torch.get_num_threads()} threads, "
              f"{metrics['train_size']:.0f} train / {metrics['val_size']:.0f} held-out trajectories")
        print(f"training wall time {wall:.1f} s (fit {metrics['train_seconds']:.1f} s), epochs {metrics['epochs']:.0f}, "
              f"steps {metrics['steps']:.0f}")
        print("| split | last-position accuracy | ceiling (best causal guess) | accuracy over all steps |")
        print("|---|---|---|---|")
        for split, (last, ceiling, every) in rows.items():
            print(f"| {split} | {last:.4f} | {ceiling:.4f} | {every:.4f} |")


if __name__ == "__main__":
    main()
