"""Benchmark of localization on the real KITTI 00 drive: every localizer from many starts beside the oracle.

Needs the kitti00 pipeline's graph and odometry (``snakemake --configfile config/regions/kitti00.yaml``; the learned
localizers also its trained model, else they are left out):

    python -m benchmarks.bench_localization [--results results/kitti00] [--model PATH]
        [--localizers metric,hmm,rnn_filter,raw,strategy1,strategy2] [--configfile FILE] [--steps 5000]
        [--set localization.rnn_filter.evidence_weight=0.5 ...]

Prints markdown:

1. per drive (``gt``, ``orbslam2``) and localizer, beside the oracle: starts, share localized, median and
   p90 distance to localized, median ratio to the oracle, accuracy after, position error, confident wrong
   (:mod:`topoloc.localization.evaluation`, a start every ``localization.evaluate.start_every_m``), and
   the CPU seconds of all starts;
2. the figures from frame 0 (distance to localized and the oracle's, accuracy after, position error);
3. the targets of the metric filter on KITTI 00, and of the learned localizer (its best decoder against the
   HMM baseline and the oracle);
4. decoding steps per second of Strategy 1 and 2 for k = 5 and k = 50 (with a model).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc.config import dotted_overrides, load
from topoloc.experiments.many_starts import evaluate_kitti
from topoloc.localization.decoders import beam_decode
from topoloc.localization.rnn import edge_log_probs
from topoloc.motion.poses import Odometry
from topoloc.motion.poses import read_poses
from topoloc.registry import make, registry

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results/kitti00", help="results folder of the kitti00 pipeline")
    parser.add_argument("--model", default=None, help="model checkpoint (default: RESULTS/model/model.ckpt, if present)")
    parser.add_argument("--localizers", default="metric,hmm,rnn_filter,raw,strategy1,strategy2")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="override config keys")
    parser.add_argument("--configfile", default=str(REPO / "config" / "config.yaml"))
    parser.add_argument("--steps", type=int, default=5000, help="steps of the decoding-speed runs")
    add_out_option(parser, "bench_localization")
    args = parser.parse_args(argv)
    with markdown_copy(args.out):
        conf = load(args.configfile, dotted_overrides(args.set))
        results = Path(args.results)
        model_path = Path(args.model or results / "model" / "model.ckpt")
        known = registry()
        names = [n for n in args.localizers.split(",") if not known[n].requires_model or model_path.is_file()]
        table, summary, seconds, road = evaluate_kitti(results, conf, names, model_path)
        model, graph = road.model, road.graph
        ev = conf["localization"]["evaluate"]
        lconf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
        cols = ["drive", "localizer", "starts", "localized_share", "median_m", "p90_m", "median_ratio", "accuracy_after",
                "position_error_m", "confident_wrong", "ece", "cpu_s"]
        print(f"## KITTI 00, a start every {ev['start_every_m']:.0f} m ({graph.num_edges} roads)\n")
        print(summary[cols].to_markdown(index=False, floatfmt=".3f"))
        first = table[table.start == 0][["drive", "localizer", "localized_m", "oracle_m", "accuracy_after", "position_error_m"]]
        print("\n## From frame 0\n")
        print(first.to_markdown(index=False, floatfmt=".3f"))
        if "metric" in names:
            print("\n## Targets of the metric filter on KITTI 00\n")
            for drive in ("gt", "orbslam2"):
                zero = first[(first.drive == drive) & (first.localizer == "metric")].iloc[0]
                s = summary[(summary.drive == drive) & (summary.localizer == "metric")].iloc[0]
                o = summary[(summary.drive == drive) & (summary.localizer == "oracle")].iloc[0]
                resolved = table[(table.drive == drive) & (table.localizer == "metric") & np.isfinite(table.oracle_m)]
                print(f"- {drive}: from frame 0 localized after {zero.localized_m:.0f} m, oracle {zero.oracle_m:.0f} m "
                      f"(ratio {zero.localized_m / zero.oracle_m:.2f}, target <= 1.2), accuracy after {zero.accuracy_after:.3f} "
                      f"(>= 0.98); median over starts {s.median_m:.0f} m vs oracle {o.median_m:.0f} m (ratio "
                      f"{s.median_m / o.median_m:.2f}, <= 1.3); median position error {s.position_error_m:.2f} m (<= 5); "
                      f"starts the oracle resolves localized: {np.isfinite(resolved.localized_m).mean():.3f}, all starts "
                      f"{s.localized_share:.3f}; CPU of all starts {seconds[(drive, 'metric')]:.2f} s (<= 10)")
        learned = [n for n in names if known[n].requires_model]
        if learned and "hmm" in names:
            print("\n## Targets of the learned localizer on KITTI 00\n")
            for drive in ("gt", "orbslam2"):
                rows_of = summary[summary.drive == drive].set_index("localizer")
                best = min(learned, key=lambda n: (rows_of.loc[n, "median_m"], -rows_of.loc[n, "accuracy_after"]))
                b, h, o = rows_of.loc[best], rows_of.loc["hmm"], rows_of.loc["oracle"]
                print(f"- {drive}: best learned decoder {best}: median {b.median_m:.0f} m vs HMM {h.median_m:.0f} m "
                      f"(ahead: {b.median_m < h.median_m}), accuracy after {b.accuracy_after:.3f} vs HMM {h.accuracy_after:.3f} "
                      f"(ahead: {b.accuracy_after > h.accuracy_after}); median / oracle median {b.median_m / o.median_m:.2f} "
                      f"(<= 2), median ratio {b.median_ratio:.2f}; accuracy after >= 0.95: {b.accuracy_after >= 0.95}")
        if model is not None:
            print(f"\n## Decoding speed ({args.steps} steps: the gt drive's RNN outputs repeated)\n")
            print("| decoder | k | steps/s |\n|---|---|---|")
            items = make("raw").observe(Odometry.from_poses(read_poses(results / "odometry" / "gt" / "poses.txt")), road, lconf).items
            tokens = np.asarray([i[0] if isinstance(i, tuple) else i for i in items])
            inputs = np.stack([i[1] for i in items]) if isinstance(items[0], tuple) else None
            logp = edge_log_probs(model, tokens, conf["localization"]["rnn"]["window"], conf["localization"]["rnn"]["stride"], inputs)
            long = np.concatenate([logp] * (args.steps // len(logp) + 1))[: args.steps]
            for strategy in ("strategy1", "strategy2"):
                for k in (5, 50):
                    began = time.perf_counter()
                    beam_decode(long, road.states, strategy, k, reseed=conf["localization"]["decode"]["reseed"])
                    print(f"| {known[strategy].label} | {k} | {args.steps / (time.perf_counter() - began):,.0f} |")
        return 0


if __name__ == "__main__":
    sys.exit(main())
