"""Benchmark of localization on KITTI 00: accuracy of every decoder, full-drive time, decoding steps per second.

Needs the kitti00 pipeline's model, graph and segments (``snakemake --configfile config/kitti00.yaml``):

    PYTHONPATH=src python benchmarks/bench_localization.py [--results results/kitti00] [--model PATH]

Prints markdown:

1. per drive (``gt``, ``orbslam2``) and decoder (raw, Strategy 1, Strategy 2, HMM): step accuracy
   (online and decoded sequence), consistency, distance until localized and accuracy after it
   (:mod:`topoloc.localization.metrics`, ``localization.evaluate.confirm_m`` of config/config.yaml);
2. the time to localize the whole 4541-frame drive from its poses file: Douglas-Peucker segmentation and
   encoding, the RNN (windowed) and the raw, Strategy 1 and Strategy 2 decoders (median of ``--repeats``
   runs; the HMM baseline timed apart); model loading and imports are not included;
3. decoding steps per second of Strategy 1 and 2 for k = 5 and k = 50, on the drive's RNN outputs
   repeated to ``--steps`` steps.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.decoders import beam_decode
from topoloc.localization.localize import LABELS, Localizer
from topoloc.localization.metrics import drive_metrics
from topoloc.localization.rnn import edge_log_probs, load_model
from topoloc.odometry.poses import planar_track, read_poses
from topoloc.odometry.segment_trajectory import encode_track

REPO = Path(__file__).resolve().parents[1]
KITTI00 = REPO.parent / "shared" / "data" / "kitti00"


def timed(function, repeats: int) -> tuple[float, object]:
    """Median seconds of ``repeats`` calls, and the last result."""
    seconds, result = [], None
    for _ in range(repeats):
        started = time.perf_counter()
        result = function()
        seconds.append(time.perf_counter() - started)
    return statistics.median(seconds), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results/kitti00", help="results folder of the kitti00 pipeline")
    parser.add_argument("--model", default=None, help="model checkpoint (default: RESULTS/model/model.ckpt)")
    parser.add_argument("--configfile", default=None, help="config overriding config/config.yaml (localization, segmentation)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--steps", type=int, default=5000, help="steps of the decoding-speed runs")
    args = parser.parse_args()
    conf = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    if args.configfile:
        extra = yaml.safe_load(Path(args.configfile).read_text()) or {}
        for key in ("localization", "segmentation", "encoding"):
            for sub, value in (extra.get(key) or {}).items():
                conf[key][sub] = value if not isinstance(value, dict) else {**conf[key][sub], **value}
    results = Path(args.results)
    graph = RoadGraph.load(results / "graph" / "graph.graphml")
    model = load_model(args.model or str(results / "model" / "model.ckpt"))
    localizer = Localizer(model, graph, conf["localization"])
    states = localizer.states
    confirm = float(conf["localization"]["evaluate"]["confirm_m"])

    print(f"## Localization on KITTI 00 ({graph.num_edges} edges; k = {conf['localization']['decode']['k']}, "
          f"RNN window {conf['localization']['rnn']['window']} / stride {conf['localization']['rnn']['stride']})\n")
    print("| drive | decoder | steps | step acc. (online) | step acc. (decoded seq.) | consistency | localized after (m) "
          "| online acc. after | decoded acc. after |")
    print("|---|---|---|---|---|---|---|---|---|")
    logps = {}
    for drive in ("gt", "orbslam2"):
        tokens = pd.read_csv(results / "segments" / drive / "tokens.csv")
        result = localizer.localize(tokens.token.to_numpy(np.int64))
        logps[drive] = result.logp
        truth = tokens.edge_id.to_numpy()
        for name, dec in result.decoded.items():
            m = drive_metrics(truth, dec.online, dec.path, tokens.distance_m.to_numpy(float), states, confirm)
            loc = f"{m['localized_m']:.0f}" if np.isfinite(m["localized_m"]) else "never"
            after = f"{m['accuracy_after']:.3f}" if np.isfinite(m["accuracy_after"]) else "-"
            pafter = f"{m['path_accuracy_after']:.3f}" if np.isfinite(m["path_accuracy_after"]) else "-"
            print(f"| {drive} | {LABELS[name]} | {len(truth)} | {m['accuracy']:.3f} | {m['path_accuracy']:.3f} "
                  f"| {m['consistency']:.3f} | {loc} | {after} | {pafter} |")

    print("\n## Whole-drive localization time (median of %d runs; this CPU, 1 process)\n" % args.repeats)
    print("| poses | frames | tokens | segmentation (s) | RNN (s) | raw + S1 + S2 (s) | total (s) | HMM baseline (s) |")
    print("|---|---|---|---|---|---|---|---|")
    seg = conf["segmentation"]
    for drive in ("gt", "orbslam2"):
        xy = planar_track(read_poses(KITTI00 / "poses" / f"00_{drive}.txt"))

        def segment():
            return encode_track(xy, graph.virtual_node_spacing_m, int(model.hparams.bins), float(seg["tolerance_m"]),
                                float(conf["encoding"]["heading_lookahead_m"]), float(seg["turn_label_offset_m"]),
                                float(seg["corner_skip_m"])).encoded.tokens

        t_seg, tokens = timed(segment, args.repeats)
        t_rnn, logp = timed(lambda: edge_log_probs(model, tokens, conf["localization"]["rnn"]["window"],
                                                    conf["localization"]["rnn"]["stride"]), args.repeats)
        opts = localizer.beam_options()
        t_dec, _ = timed(lambda: [logp.argmax(1), beam_decode(logp, states, "strategy1", **opts),
                                  beam_decode(logp, states, "strategy2", **opts)], args.repeats)
        t_hmm, _ = timed(lambda: localizer.hmm.decode(tokens), max(1, args.repeats // 2))
        print(f"| 00_{drive}.txt | {len(xy)} | {len(tokens)} | {t_seg:.4f} | {t_rnn:.4f} | {t_dec:.4f} "
              f"| **{t_seg + t_rnn + t_dec:.3f}** | {t_hmm:.3f} |")

    print(f"\n## Decoding speed ({args.steps} steps: the gt drive's RNN outputs repeated)\n")
    print("| decoder | k | steps/s |")
    print("|---|---|---|")
    base = logps["gt"]
    long = np.concatenate([base] * (args.steps // len(base) + 1))[: args.steps]
    for strategy in ("strategy1", "strategy2"):
        for k in (5, 50):
            opts = {**localizer.beam_options(), "k": k}
            seconds, _ = timed(lambda: beam_decode(long, states, strategy, **opts), max(1, args.repeats // 2))
            print(f"| {LABELS[strategy]} | {k} | {args.steps / seconds:,.0f} |")


if __name__ == "__main__":
    main()
