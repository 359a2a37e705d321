"""Dataset generation benchmark: throughput on both maps and peak memory up to 1 million trajectories.

Usage (after `snakemake all` for both configs built the graphs)::

    python -m benchmarks.bench_dataset [--sizes 100000 1000000]

Each measurement runs in a fresh subprocess so that its peak RSS
(``ru_maxrss``) is its own. Output files go to a temporary directory.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.markdown import add_out_option, markdown_copy

GRAPHS = {"helsinki": "results/helsinki/graph/graph.graphml", "kitti00": "results/kitti00/graph/graph.graphml"}


def conf(path_nodes: int, respect_oneway: bool, max_total: int | None) -> dict:
    """The ``generate_dataset`` slice of the schema defaults with these dataset settings."""
    from topoloc.config import load

    config = load(None, {"dataset": {"path_nodes": path_nodes, "respect_oneway": respect_oneway,
                                     "max_paths_total": max_total}})
    return {"encoding": config["encoding"], "dataset": config["dataset"]}


def measure(graph_path: str, path_nodes: int, respect_oneway: bool, max_total: int | None) -> dict:
    """Generate one dataset in this process; its statistics, wall time, file sizes and peak RSS."""
    from topoloc.graph.road_graph import RoadGraph
    from topoloc.trajectory.generate_dataset import generate

    graph = RoadGraph.load(graph_path)
    with tempfile.TemporaryDirectory() as tmp:
        started = time.perf_counter()
        stats = generate(graph, conf(path_nodes, respect_oneway, max_total), f"{tmp}/t.parquet", f"{tmp}/v.parquet")
        wall = time.perf_counter() - started
        size = sum(p.stat().st_size for p in Path(tmp).glob("*.parquet"))
    return {"trajectories": stats["trajectories"], "seconds": round(wall, 2),
            "trajectories_per_s": round(stats["trajectories"] / wall), "parquet_mb": round(size / 2**20, 1),
            "tokens_mean": round(stats["tokens_mean"], 1),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)}


def child(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_dataset", "--child", *args],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=int, nargs="*", default=[100_000, 1_000_000])
    parser.add_argument("--child", nargs=4)
    add_out_option(parser, "bench_dataset")
    args = parser.parse_args()
    if args.child:
        graph, nodes, oneway, total = args.child
        print(json.dumps(measure(graph, int(nodes), oneway == "1", None if total == "0" else int(total))))
        return
    with markdown_copy(args.out):
        rows = []
        for name, graph in GRAPHS.items():
            if not Path(graph).exists():
                print(f"skip {name}: {graph} missing (run snakemake for it first)")
                continue
            rows.append({"map": name, "setting": "default (10 nodes, one-way respected, all paths)", **child(graph, "10", "1", "0")})
        if Path(GRAPHS["helsinki"]).exists():
            for size in args.sizes:  # 13-node paths ignoring one-way: far more than 1M exist, capped by max_paths_total
                rows.append({"map": "helsinki", "setting": f"13 nodes, both directions, max_paths_total={size}",
                             **child(GRAPHS["helsinki"], "13", "0", str(size))})
        keys = ["map", "setting", "trajectories", "seconds", "trajectories_per_s", "tokens_mean", "parquet_mb", "peak_rss_mb"]
        print("| " + " | ".join(keys) + " |")
        print("|" + "---|" * len(keys))
        for row in rows:
            print("| " + " | ".join(str(row[k]) for k in keys) + " |")


if __name__ == "__main__":
    main()
