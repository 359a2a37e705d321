"""Per-rule threads, memory and run time for a scheduler, measured from Snakemake's benchmark files.

Reads every ``results/<region>/benchmarks/<rule>[_<wildcards>].tsv`` under the given results folders, takes
the largest figures of each rule over regions and wildcards (not the experiments of ``experiments.smk``), adds
headroom, and writes them as the ``set-threads`` / ``set-resources`` of the cluster profiles (between the
``# measured resources`` markers of ``profiles/slurm/config.yaml`` and ``profiles/slurm-gpu/config.yaml``; the
GPU profile adds ``gpu: 1`` to the training rules)::

    python cluster/measure_resources.py ../fresh/results [--write]

* ``threads``: the mean CPU load of the job (``mean_load``, % of one core), rounded up to whole cores (not for
  rules whose ``threads:`` come from the config, e.g. ``place.threads``: the stage uses that many);
* ``mem_mb``: 1.5 x the peak resident memory (``max_rss``), rounded up to 256 MB, at least 512;
* ``runtime`` (minutes): 3 x the wall time (a loaded node, another map), at least 10; a training rule at least
  its ``max_time_min`` safety cap plus 10 (the cap, not the scheduler, must end a slow training).

Without ``--write`` the block is printed. A rule of the workflow without a benchmark file is an error.
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import sys
from pathlib import Path

from topoloc.config import load

REPO = Path(__file__).resolve().parents[1]
PROFILES = {"slurm": {}, "slurm-gpu": {"train_rnn": {"gpu": 1}, "train_retrieval": {"gpu": 1}, "train_controller": {"gpu": 1}}}
BEGIN, END = "# measured resources: begin", "# measured resources: end"
#: Rules that read no benchmark figures: the target rule.
UNMEASURED = {"all"}
#: Rule files left out: the experiments are long runs off ``rule all``, on the profiles' default resources.
UNMEASURED_FILES = {"experiments.smk"}


def workflow_rules() -> dict[str, bool]:
    """The rules of ``workflow/rules/*.smk`` (but :data:`UNMEASURED_FILES`), each with whether it sets its threads
    from the config."""
    rules = {}
    for path in sorted((REPO / "workflow" / "rules").glob("*.smk")):
        if path.name in UNMEASURED_FILES:
            continue
        blocks = re.split(r"^(?=\s*(?:rule|checkpoint) \w+:)", path.read_text(), flags=re.MULTILINE)
        for text in blocks:
            name = re.match(r"\s*(?:rule|checkpoint) (\w+):", text)
            if name:
                rules[name.group(1)] = bool(re.search(r"^\s+threads: config\[", text, flags=re.MULTILINE))
    return rules


def benchmark_rows(results: list[Path], rules: list[str]) -> dict[str, list[dict[str, float]]]:
    """Benchmark rows per rule (the longest rule name that prefixes a file's name owns it)."""
    rows: dict[str, list[dict[str, float]]] = {}
    by_length = sorted(rules, key=len, reverse=True)
    for path in sorted(p for folder in results for p in folder.glob("*/benchmarks/*.tsv")):
        rule = next((r for r in by_length if path.stem == r or path.stem.startswith(r + "_")), None)
        if rule is None:
            continue
        with open(path) as handle:
            for row in csv.DictReader(handle, delimiter="\t"):
                rows.setdefault(rule, []).append({k: float(row[k]) for k in ("s", "max_rss", "mean_load")})
    return rows


def time_caps() -> dict[str, float]:
    """The training rules' ``max_time_min`` safety caps in the default config (schema defaults filled in)."""
    config = load(REPO / "config" / "config.yaml")
    return {"train_rnn": config["train"]["max_time_min"], "train_retrieval": config["place"]["train"]["max_time_min"],
            "train_controller": config["drive"]["train"]["max_time_min"]}


def resources(rows: list[dict[str, float]], cap_min: float | None) -> tuple[int, dict[str, int]]:
    """Threads and ``mem_mb`` / ``runtime`` of one rule from its benchmark rows."""
    threads = max(1, math.ceil(max(r["mean_load"] for r in rows) / 100.0))
    mem_mb = max(512, 256 * math.ceil(1.5 * max(r["max_rss"] for r in rows) / 256))
    runtime = max(10, math.ceil(3 * max(r["s"] for r in rows) / 60))
    if cap_min is not None:
        runtime = max(runtime, math.ceil(cap_min) + 10)
    return threads, {"mem_mb": mem_mb, "runtime": runtime}


def block(measured: dict[str, tuple[int, dict[str, int]]], extra: dict[str, dict[str, int]]) -> str:
    """The profile lines between the markers."""
    lines = [BEGIN + " (cluster/measure_resources.py; do not edit by hand)", "set-threads:"]
    lines += [f"  {rule}: {threads}" for rule, (threads, _) in measured.items() if threads]
    lines.append("set-resources:")
    for rule, (_, res) in measured.items():
        res = res | extra.get(rule, {})
        lines.append(f"  {rule}: {{{', '.join(f'{k}: {v}' for k, v in res.items())}}}")
    return "\n".join([*lines, END])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path, help="results folders holding <region>/benchmarks/")
    parser.add_argument("--write", action="store_true", help="rewrite the profiles' measured block")
    args = parser.parse_args()
    configured = workflow_rules()
    rules = [r for r in configured if r not in UNMEASURED]
    rows = benchmark_rows(args.results, rules)
    missing = [r for r in rules if r not in rows]
    if missing:
        sys.exit(f"measure_resources: no benchmark file for rule(s) {', '.join(missing)} under "
                 f"{', '.join(map(str, args.results))}")
    caps = time_caps()
    measured = {rule: resources(rows[rule], caps.get(rule)) for rule in rules}
    measured = {rule: (0 if configured[rule] else threads, res) for rule, (threads, res) in measured.items()}
    for name, extra in PROFILES.items():
        text = block(measured, extra)
        if not args.write:
            print(f"# profiles/{name}/config.yaml\n{text}")
            continue
        path = REPO / "profiles" / name / "config.yaml"
        current = path.read_text()
        start, end = current.index(BEGIN), current.index(END) + len(END)
        path.write_text(current[:start] + text + current[end:])
        print(f"wrote {len(measured)} rules to {path.relative_to(REPO)}")


if __name__ == "__main__":
    main()
