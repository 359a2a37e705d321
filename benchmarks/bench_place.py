"""Benchmark of place recognition: embedding speed and the teach-and-repeat localization targets.

Usage (after ``snakemake all`` built ``results/<region>/teach_repeat``)::

    python -m benchmarks.bench_place [--region helsinki] [--repeats 5] [--threads 1 2]
        [--odometry-seeds 1 2] [--configfile config/config.yaml]

Prints markdown:

- the localization table of ``results/<region>/teach_repeat/summary.csv`` (share of repeat frames within
  5 m and 2 m, relocalizations, per condition and method: the paper's loop and the Bayes filter, each with
  the network and the raw-correlation baseline) against the targets: at least 90 % within 5 m in every
  condition, ahead of the raw-correlation baseline;
- the share within 5 m again with other draws of the repeat drives' odometry noise (``--odometry-seeds``):
  one draw can be lucky or unlucky, the loop's failures cascade;
- embedding speed of the trained network (``results/<region>/retrieval/model.ckpt``) on the repeat images
  at the network's input size, batches of 256, for each ``--threads`` torch thread count: images per
  wall-clock second (median of ``--repeats``) and per CPU second; target >= 200 images/s. The load average
  is printed beside it: on a shared machine the wall-clock figure depends on the other jobs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import pandas as pd
import torch

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc.place.images import PlaceSet
from topoloc.place.network import load_model


def embedding_speed(model_path: Path, places_path: Path, threads: int, repeats: int, n: int = 1024) -> dict[str, float]:
    """Images/s of ``model.embed`` on ``n`` repeat images with ``threads`` torch threads."""
    torch.set_num_threads(threads)
    model = load_model(model_path)
    images = PlaceSet.load(places_path).images.reshape(-1, *PlaceSet.load(places_path).images.shape[2:])[:n]
    model.embed(images[:256])  # warm-up
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        model.embed(images, batch_size=256)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return {"threads": threads, "images": len(images), "size": "x".join(map(str, images.shape[1:3][::-1])),
            "images_per_s": len(images) / statistics.median(wall), "images_per_cpu_s": len(images) / statistics.median(cpu)}


def localization_table(summary: pd.DataFrame, held_out: list[str]) -> str:
    """Per condition and method: within 5 m, within 2 m, relocalizations; the mean; the target check."""
    conditions = list(dict.fromkeys(summary.condition))
    head = ["method", "Mean", *[f"{c} (held out)" if c in held_out else c for c in conditions], "min", ">= 90 % everywhere"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for method in dict.fromkeys(summary.method):
        rows = summary[summary.method == method].set_index("condition").loc[conditions]
        cells = [f"{a:.3f} / {b:.3f} / {int(r)}" for a, b, r in zip(rows.within_5m, rows.within_2m, rows.relocalizations)]
        lines.append("| " + " | ".join([method, f"{rows.within_5m.mean():.3f}", *cells, f"{rows.within_5m.min():.3f}",
                                        "yes" if rows.within_5m.min() >= 0.9 else "**no**"]) + " |")
    return "\n".join(lines)


def odometry_seeds(root: Path, seeds: list[int], configfile: Path) -> str:
    """Within 5 m per method and condition, rerunning ``localize_repeat`` with other odometry noise seeds."""
    import tempfile

    from topoloc.config import load
    from topoloc.place.localize_repeat import run

    place = load(configfile)["place"]
    rows = []
    for seed in seeds:
        conf = {k: place[k] for k in ("threads", "teach_condition", "repeat_conditions", "odometry_noise", "localize")}
        conf |= {"seed": seed, "train": {"conditions": place["train"]["conditions"]}}
        with tempfile.TemporaryDirectory() as tmp:
            names = {"frames": "f.csv", "summary": "s.csv", "metrics": "m.json", "table": "t.md", "bars": "b.png",
                     "errors": "e.png"}
            outputs = {k: str(Path(tmp) / v) for k, v in names.items()}
            run(conf, {"model": str(root / "retrieval" / "model.ckpt"), "map": str(root / "topometric_map" / "map.npz"),
                       "repeat": str(root / "places" / "repeat" / "places.npz")}, outputs)
            rows.append(pd.read_csv(outputs["summary"]).assign(seed=seed))
    frame = pd.concat(rows)
    conditions = list(dict.fromkeys(frame.condition))
    lines = ["| method | seed | " + " | ".join(conditions) + " | min |", "|" + "---|" * (len(conditions) + 3)]
    for (method, seed), g in frame.groupby(["method", "seed"], sort=False):
        values = g.set_index("condition").loc[conditions, "within_5m"]
        lines.append(f"| {method} | {seed} | " + " | ".join(f"{v:.3f}" for v in values) + f" | {values.min():.3f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--region", default="helsinki")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--odometry-seeds", type=int, nargs="*", default=[1, 2],
                        help="rerun the localization with these odometry noise seeds (place.seed of config/config.yaml "
                             "is the stage's own)")
    parser.add_argument("--configfile", type=Path, default=Path("config/config.yaml"))
    add_out_option(parser, "bench_place")
    args = parser.parse_args()
    with markdown_copy(args.out):
        root = Path("results") / args.region
        summary = pd.read_csv(root / "teach_repeat" / "summary.csv")
        metrics = json.loads((root / "teach_repeat" / "metrics.json").read_text())
        train = json.loads((root / "retrieval" / "train_metrics.json").read_text())
        stats = json.loads((root / "places" / "train" / "stats.json").read_text())
        held_out = sorted(set(summary.condition[summary.held_out]))
        print(f"## Localization ({args.region}): within 5 m / within 2 m / relocalizations\n")
        print(localization_table(summary, held_out))
        within = summary.pivot(index="condition", columns="method", values="within_5m")
        ahead = {loop: bool((within[f"siamese network{loop}"] >= within[f"raw correlation{loop}"]).all()
                            and within[f"siamese network{loop}"].mean() > within[f"raw correlation{loop}"].mean())
                 for loop in ("", " + filter")}
        print(f"\nnetwork ahead of raw correlation (not behind in any condition, ahead on the mean): "
              f"paper loop {'yes' if ahead[''] else '**no**'}, filter {'yes' if ahead[' + filter'] else '**no**'}; "
              f"training: {train['steps']:.0f} steps in {train['train_seconds']:.0f} s; "
              f"training places at least {stats['min_distance_to_route_m']:.0f} m from the evaluation route\n")
        if args.odometry_seeds:
            print("## Within 5 m with other odometry noise draws (same network, map and images)\n")
            print(odometry_seeds(root, args.odometry_seeds, args.configfile) + "\n")
        print(f"## Embedding speed (target >= 200 images/s); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs\n")
        print("| threads | images | size | images/s | images per CPU second |\n|---|---|---|---|---|")
        for threads in args.threads:
            r = embedding_speed(root / "retrieval" / "model.ckpt", root / "places" / "repeat" / "places.npz", threads, args.repeats)
            print(f"| {r['threads']} | {r['images']} | {r['size']} | {r['images_per_s']:.0f} | {r['images_per_cpu_s']:.0f} |")
        print(f"\nin the localize_repeat stage: {metrics['embed_images_per_s']:.0f} images/s")


if __name__ == "__main__":
    main()
