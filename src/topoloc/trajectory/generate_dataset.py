"""Stage ``generate_dataset``: training trajectories of the road graph, as tokens and edge labels.

``dataset.source``: ``simulated_drives`` (:mod:`topoloc.trajectory.drives`: simulated noisy drives encoded as
test drives are, with continuous per-token features) or ``dfs`` (the paper: simple map paths,
:mod:`topoloc.trajectory.paths`). Outputs ``train.parquet`` and ``val.parquet`` (split by whole drives or
paths, from the seed), ``stats.json`` and the paper's Table I as markdown.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
from tqdm import tqdm

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.io import atomic_path, write_json, write_text
from topoloc.segmentation import TOKEN_FEATURES
from topoloc.trajectory.dataset import Noise, PathEncoder, ShardWriter
from topoloc.trajectory.drives import training_drives
from topoloc.trajectory.paths import Path, sample_paths

log = logging.getLogger(__name__)


def generate(graph: RoadGraph, conf: dict[str, Any], train_path: str, val_path: str) -> dict[str, Any]:
    """Write the dataset of ``graph`` to the two Parquet files; return its statistics."""
    if conf["dataset"]["source"] == "simulated_drives":
        return generate_drives(graph, conf, train_path, val_path)
    data = conf["dataset"]
    bins = int(conf["encoding"]["angle_bins"])
    path_nodes = int(data["path_nodes"])
    if path_nodes > len(graph.nodes):
        raise InputError("dataset.path_nodes", f"{path_nodes} nodes per path, but the graph has only {len(graph.nodes)} nodes")
    val_fraction = float(data["val_fraction"])
    aug = data["augment"]
    noise = Noise(int(aug["copies"]), float(aug["angle_std_deg"]), float(aug["spacing_rel_std"]))
    seed = int(data["seed"])
    mode = data["encoding"]
    if mode == "douglas_peucker" and "segmentation" not in conf:
        raise InputError("dataset.encoding", "douglas_peucker needs the segmentation config")
    encoder = PathEncoder(graph, bins, float(conf["encoding"]["heading_lookahead_m"]),
                          conf["segmentation"] if mode == "douglas_peucker" else None)
    split_rng = np.random.default_rng([seed, 1])
    noise_rng = np.random.default_rng([seed, 2])

    counts = {"train": 0, "val": 0}
    train_classes = np.zeros(graph.num_edges, dtype=bool)
    all_classes = np.zeros(graph.num_edges, dtype=bool)
    lengths: list[int] = []
    started = time.perf_counter()
    with atomic_path(train_path) as train_tmp, atomic_path(val_path) as val_tmp:
        writers = {"train": ShardWriter(train_tmp, int(data["shard_rows"])), "val": ShardWriter(val_tmp, int(data["shard_rows"]))}
        paths = sample_paths(
            graph,
            path_nodes,
            respect_oneway=bool(data["respect_oneway"]),
            max_per_source=data["max_paths_per_source"],
            max_total=data["max_paths_total"],
            seed=seed,
        )
        for path_id, path in enumerate(paths):
            split = "val" if split_rng.random() < val_fraction else "train"
            tokens, labels = encoder.encode(path)
            writers[split].add(path_id, 0, path, tokens, labels)
            counts[split] += 1
            lengths.append(len(tokens))
            all_classes[labels] = True
            if split == "train":
                train_classes[labels] = True
                for copy in range(1, noise.copies + 1):
                    noisy_tokens, noisy_labels = encoder.encode(path, noise_rng, noise)
                    writers[split].add(path_id, copy, path, noisy_tokens, noisy_labels)
        for writer in writers.values():
            writer.close()
        elapsed = time.perf_counter() - started
        paths_total = counts["train"] + counts["val"]
        if paths_total == 0:
            raise InputError("dataset.path_nodes", f"no simple path with {path_nodes} nodes in this graph (respect_oneway={data['respect_oneway']})")
        if counts["train"] == 0 or (val_fraction > 0 and counts["val"] == 0):
            raise InputError("dataset.val_fraction", f"split of {paths_total} paths leaves {counts['train']} train / {counts['val']} validation paths")
    lengths_arr = np.asarray(lengths)
    return {
        "map_nodes": int(len(graph.nodes)),
        "map_edges": int(graph.num_edges),
        "path_nodes": path_nodes,
        "trajectories": int(paths_total),
        "train_trajectories": int(counts["train"]),
        "val_trajectories": int(counts["val"]),
        "augmented_train_rows": int(counts["train"] * noise.copies),
        "classes": int(graph.num_edges),
        "classes_seen": int(all_classes.sum()),
        "train_classes_seen": int(train_classes.sum()),
        "input_feature_space": bins,
        "tokens_min": int(lengths_arr.min()),
        "tokens_mean": float(lengths_arr.mean()),
        "tokens_max": int(lengths_arr.max()),
        "seconds": elapsed,
        "trajectories_per_s": paths_total * (1 + noise.copies) / max(elapsed, 1e-9),
        "feature_dim": 0,
    }


def generate_drives(graph: RoadGraph, conf: dict[str, Any], train_path: str, val_path: str) -> dict[str, Any]:
    """The ``simulated_drives`` source: write the drives of :mod:`topoloc.trajectory.drives`; their statistics."""
    data = conf["dataset"]
    sim = data["simulated"]
    dim = len(TOKEN_FEATURES) if sim["features"] else 0
    val_fraction = float(data["val_fraction"])
    split_rng = np.random.default_rng([int(data["seed"]), 1])
    counts = {"train": 0, "val": 0}
    train_classes = np.zeros(graph.num_edges, dtype=bool)
    all_classes = np.zeros(graph.num_edges, dtype=bool)
    lengths, metres = [], []
    started = time.perf_counter()
    with atomic_path(train_path) as train_tmp, atomic_path(val_path) as val_tmp:
        writers = {"train": ShardWriter(train_tmp, int(data["shard_rows"])), "val": ShardWriter(val_tmp, int(data["shard_rows"]))}
        drives = training_drives(graph, conf, int(data["seed"]))
        for drive_id, drive in enumerate(tqdm(drives, total=int(sim["drives"]), desc="simulated drives", unit="drive",
                                              mininterval=5.0)):
            split = "val" if split_rng.random() < val_fraction else "train"
            writers[split].add(drive_id, 0, Path(tuple(drive.nodes), tuple(drive.edges)), drive.tokens, drive.labels,
                               drive.features[:, :dim])
            counts[split] += 1
            lengths.append(len(drive.tokens))
            metres.append(drive.length_m)
            all_classes[drive.labels] = True
            if split == "train":
                train_classes[drive.labels] = True
        for writer in writers.values():
            writer.close()
        if counts["train"] == 0 or (val_fraction > 0 and counts["val"] == 0):
            raise InputError("dataset.val_fraction", f"split of {sum(counts.values())} drives leaves {counts['train']} train / "
                                                     f"{counts['val']} validation drives")
    elapsed = time.perf_counter() - started
    lengths_arr = np.asarray(lengths)
    return {
        "source": "simulated_drives",
        "map_nodes": len(graph.nodes),
        "map_edges": int(graph.num_edges),
        "trajectories": len(lengths),
        "train_trajectories": int(counts["train"]),
        "val_trajectories": int(counts["val"]),
        "augmented_train_rows": 0,
        "classes": int(graph.num_edges),
        "classes_seen": int(all_classes.sum()),
        "train_classes_seen": int(train_classes.sum()),
        "input_feature_space": int(conf["encoding"]["angle_bins"]),
        "feature_dim": dim,
        "tokens_min": int(lengths_arr.min()),
        "tokens_mean": float(lengths_arr.mean()),
        "tokens_max": int(lengths_arr.max()),
        "tokens_total": int(lengths_arr.sum()),
        "metres_mean": float(np.mean(metres)),
        "seconds": elapsed,
        "trajectories_per_s": len(lengths) / max(elapsed, 1e-9),
    }


def table_i(stats: dict[str, Any], region: str) -> str:
    """The paper's Table I for this map, in markdown."""
    rows = [
        ("Topological Map", f"{stats['map_nodes']} nodes, {stats['map_edges']} edges"),
        ("Trajectory Length", (f"{stats['path_nodes']} nodes" if "path_nodes" in stats else f"simulated drives of {stats['metres_mean']:.0f} m on average")
         + f" ({stats['tokens_min']}-{stats['tokens_max']} tokens, mean {stats['tokens_mean']:.1f})"),
        ("All Trajectories", f"{stats['trajectories']}"),
        ("All Classes", f"{stats['classes']}"),
        ("Input Feature Space", f"{stats['input_feature_space']}" + (f" tokens + {stats['feature_dim']} continuous features" if stats.get("feature_dim") else "")),
        ("Training Trajectories", f"{stats['train_trajectories']}" + (f" (+{stats['augmented_train_rows']} noisy copies)" if stats["augmented_train_rows"] else "")),
        ("Validation Trajectories", f"{stats['val_trajectories']}"),
        ("Training Output Classes", f"{stats['train_classes_seen']}"),
    ]
    lines = [f"# Table I: dataset statistics ({region})", "", "| Data | Statistics |", "|---|---|"]
    lines += [f"| {name} | {value} |" for name, value in rows]
    return "\n".join(lines) + "\n"


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Generate the dataset; outputs ``train``, ``val``, ``stats``, ``table``."""
    graph = RoadGraph.load(inputs["graph"])
    stats = generate(graph, conf, outputs["train"], outputs["val"])
    log.info("dataset: %s", stats)
    write_json(outputs["stats"], stats)
    write_text(outputs["table"], table_i(stats, conf.get("region", "")))
    return {k: float(v) for k, v in stats.items() if isinstance(v, (int, float))}
