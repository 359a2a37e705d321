"""Stage write_results_pages: one markdown page per task from the region's pipeline tables, plus headline.md.

Each page holds the task's headline table (also in ``headline.md``, which the README's tables are refreshed from:
:mod:`topoloc.report.markdown`), the stage's own tables, and every benchmark report (``results/benchmarks/*.md``)
and experiment summary (``results/{region}/experiments/*/summary.md``) of that task that exists when the stage runs,
each named with its modification time. Those are found at run time, not declared as inputs, so a long experiment is
never rerun by ``snakemake all``; ``snakemake all -R write_results_pages`` picks up new ones.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pandas as pd

from topoloc.errors import InputError
from topoloc.io import write_text
from topoloc.report.markdown import Row, block, demote, render, table_under

#: Task -> page title.
TASKS = {"localization": "Localization", "trajectory": "Trajectory learning", "odometry": "Odometry",
         "place": "Place recognition", "route_following": "Route following", "pipeline": "Pipeline"}
#: Benchmark script (results/benchmarks/<name>.md) -> task; any other lands on the pipeline page.
BENCHMARKS = {
    "bench_localization": "localization", "bench_real_drives": "localization", "bench_train": "trajectory", "bench_dataset": "trajectory",
    "bench_odometry": "odometry", "bench_render": "odometry", "bench_place": "place", "bench_drive": "route_following",
    "bench_viewer": "localization", "bench_lane_offset": "route_following",
    "bench_map_errors": "localization", "bench_filter_recovery": "localization",
}
#: Experiment (results/{region}/experiments/<name>/summary.md) -> task; any other lands on the pipeline page.
EXPERIMENTS = {"simulated": "localization", "map_errors": "localization", "city": "localization",
               "rnn_ablation": "trajectory", "drive_seeds": "route_following"}
#: The guide page of each task on the docs site.
GUIDES = {"localization": "localization.md", "trajectory": "trajectory.md", "odometry": "odometry.md",
          "place": "place.md", "route_following": "route_following.md", "pipeline": "cluster.md"}


def _num(value: Any, fmt: str) -> str:
    """``value`` formatted, or "-" when missing or not finite."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, fmt)


def _percent(share: float | None) -> str:
    """A share as a percentage (``0.9`` -> ``90.0 %``), or "-"."""
    return "-" if share is None else f"{100 * share:.1f} %"


def _columns(rows: list[Row], names: Sequence[str], where: str) -> list[int]:
    """Indices of the columns ``names`` in the header of ``rows``."""
    head = rows[0]
    missing = [name for name in names if name not in head]
    if missing:
        raise InputError(where, f"table without the column(s) {missing}")
    return [head.index(name) for name in names]


def _worst(row: Row, head: Row) -> str:
    """The lowest per-condition cell of a paper-style row (the columns after Mean) as ``condition: cell``."""
    pairs = [(float(v), i) for i, v in enumerate(row[2:], start=2) if v not in ("", "-")]
    if not pairs:
        return "-"
    _, i = min(pairs)  # the first of equal values
    return f"{head[i]}: {row[i]}"


def localization_headline(region: str, text: str, where: str) -> list[Row]:
    """Rows of every localizer over all drives (the summary table's **all** rows)."""
    rows = table_under(text, "Localization", where)
    names = ["localizer", "starts", "localized", "median (m)", "median ratio to oracle", "acc. after", "position error (m)"]
    drive, *picked = _columns(rows, ["drive", *names], where)
    return [["region", *names]] + [[region, *(row[i] for i in picked)] for row in rows[1:] if row[drive].strip("*") == "all"]


def trajectory_headline(region: str, metrics: dict[str, float]) -> list[Row]:
    """The trajectory RNN alone on held-out drives, by distance driven (evaluate_rnn's metrics)."""
    metres = (200, 500, 1000, 2000)
    return [["region", "held-out trajectories", *(f"acc. at {m} m" for m in metres), "training (s)"],
            [region, _num(metrics.get("heldout_trajectories"), ".0f"),
             *(_num(metrics.get(f"heldout_acc_{m}m"), ".3f") for m in metres), _num(metrics.get("train_seconds"), ".0f")]]


def odometry_headline(region: str, drives: dict[str, dict[str, Any]]) -> list[Row]:
    """Per drive: source, length, KITTI errors against ground truth, frame labels within 5 m of their road."""
    rows = [["region", "drive", "source", "km", "t_err (%)", "r_err (deg/100 m)", "ATE (m)", "labels within 5 m"]]
    for drive, stats in drives.items():
        ev, labels = stats.get("evaluation") or {}, stats.get("labels") or {}
        rows.append([region, drive, str(stats.get("source", "-")), _num(stats.get("length_m", math.nan) / 1000, ".2f"),
                     _num(ev.get("t_err_pct"), ".2f"), _num(ev.get("r_err_deg_per_100m"), ".3f"), _num(ev.get("ate_m"), ".2f"),
                     _percent(labels.get("within_5m"))])
    return rows


def paper_headline(region: str, text: str, heading: str, first: str, where: str) -> list[Row]:
    """Mean and worst condition of each row of a paper-style table (Tables 1-2 layout) under ``heading``."""
    rows = table_under(text, heading, where)
    return [["region", first, "Mean", "worst condition"]] + [[region, row[0], row[1], _worst(row, rows[0])] for row in rows[1:]]


def pipeline_headline(region: str, jobs: pd.DataFrame, graph: dict[str, Any]) -> list[Row]:
    """The road graph's size and the jobs' total wall time and largest peak memory."""
    return [["region", "roads", "road km", "jobs", "wall time of all jobs (min)", "largest peak RSS (MB)"],
            [region, _num(graph.get("edges"), "d"), _num(graph.get("road_km"), ".1f"), str(len(jobs)),
             _num(float(jobs.s.sum()) / 60 if len(jobs) else math.nan, ".1f"),
             _num(float(jobs.max_rss.max()) if len(jobs) else math.nan, ".0f")]]


def stage_jobs(folder: Path) -> pd.DataFrame:
    """One row per benchmark file of the region's jobs (Snakemake's ``benchmark:`` TSVs), as found now."""
    rows = []
    for path in sorted(folder.glob("*.tsv")):
        table = pd.read_csv(path, sep="\t")
        if len(table):
            rows.append({"job": path.stem, "s": float(table.s.iloc[-1]), "max_rss": float(table.max_rss.iloc[-1]),
                         "cpu_time": float(table.cpu_time.iloc[-1])})
    return pd.DataFrame(rows, columns=["job", "s", "max_rss", "cpu_time"])


def found_reports(conf: dict[str, Any]) -> dict[str, list[Path]]:
    """Task -> the benchmark reports and experiment summaries that exist now."""
    found: dict[str, list[Path]] = {task: [] for task in TASKS}
    for path in sorted(Path(conf["benchmarks_dir"]).glob("*.md")):
        found[BENCHMARKS.get(path.stem, "pipeline")].append(path)
    for path in sorted(Path(conf["experiments_dir"]).glob("*/summary.md")):
        found[EXPERIMENTS.get(path.parent.name, "pipeline")].append(path)
    return found


def _modified(path: Path) -> str:
    return datetime.fromtimestamp(path.stat().st_mtime, timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def page(task: str, region: str, headline: list[Row], sources: dict[str, str], body: str, reports: list[Path],
         figures: Sequence[str]) -> str:
    """One results page: the headline table, the stage's tables, the benchmarks and experiments found."""
    lines = [f"# {TASKS[task]}: {region}", "",
             f"Generated by the rule `write_results_pages` from the outputs of region `{region}`; do not edit. The "
             f"method and how to run it: the guide [{TASKS[task]}](../../{GUIDES[task]}).", "",
             "## Headline", "", block(task, render(headline)),
             "Sources: " + ", ".join(f"`{p}`" for p in sources.values()) + ".", ""]
    if figures:
        lines += ["Figures: " + ", ".join(f"`{f}`" for f in figures) + ".", ""]
    if body:
        lines += ["## The stages' tables", "", demote(body, 2).rstrip(), ""]
    lines += ["## Benchmarks and experiments", ""]
    if not reports:
        lines += ["None found when this page was made (`results/benchmarks/*.md`, "
                  f"`results/{region}/experiments/*/summary.md`). Run them (`python -m benchmarks.<name>`, "
                  "`snakemake experiment_<name>`), then `snakemake all -R write_results_pages`.", ""]
    for path in reports:
        lines += [f"### `{path}` (modified {_modified(path)})", "", demote(path.read_text(), 3).rstrip(), ""]
    return "\n".join(lines)


def _read(inputs: dict[str, str], key: str) -> str:
    return Path(inputs[key]).read_text()


def _json(inputs: dict[str, str], key: str) -> dict[str, Any]:
    return json.loads(Path(inputs[key]).read_text())


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Write ``outputs[task]`` for every task of :data:`TASKS` and ``outputs['headline']``."""
    region = conf["region"]
    reports = found_reports(conf)
    drives = {key.removeprefix("odometry_"): _json(inputs, key) for key in inputs if key.startswith("odometry_")}
    controllers = {key.removeprefix("controller_"): _json(inputs, key) for key in inputs if key.startswith("controller_")}
    jobs = stage_jobs(Path(conf["stage_benchmarks_dir"]))
    check = [["controller", "check routes", "success rate", "share driven"]] + [
        [name, _num(m.get("check/routes"), ".0f"), _num(m.get("check/success_rate"), ".2f"), _num(m.get("check/share_driven"), ".2f")]
        for name, m in controllers.items()]
    job_table = [["job", "wall (s)", "peak RSS (MB)", "CPU (s)"]] + [
        [r.job, f"{r.s:.0f}", f"{r.max_rss:.0f}", f"{r.cpu_time:.0f}"] for r in jobs.itertuples()]
    made: dict[str, tuple[list[Row], dict[str, str], str, list[str]]] = {
        "localization": (localization_headline(region, _read(inputs, "localization"), inputs["localization"]),
                         {"table": inputs["localization"]}, _read(inputs, "localization"),
                         [f"results/{region}/localization/localized_cdf.png", f"results/{region}/localization/reliability.png",
                          f"results/{region}/localization/fig9_<drive>.png"]),
        "trajectory": (trajectory_headline(region, _json(inputs, "evaluation")),
                       {"metrics": inputs["evaluation"], "table": inputs["accuracy"], "dataset": inputs["dataset"]},
                       _read(inputs, "dataset") + "\n" + _read(inputs, "accuracy"),
                       [f"results/{region}/evaluation/fig8a_loss.png", f"results/{region}/evaluation/fig8b_accuracy.png"]),
        "odometry": (odometry_headline(region, drives), {k: inputs[k] for k in inputs if k.startswith("odometry_")}, "",
                     [f"results/{region}/odometry/<drive>/evaluation.png", f"results/{region}/segments/<drive>/"]),
        "place": (paper_headline(region, _read(inputs, "teach_repeat"), "Share of repeat frames localized within 5 m",
                                 "method", inputs["teach_repeat"]),
                  {"table": inputs["teach_repeat"]}, _read(inputs, "teach_repeat"), [f"results/{region}/teach_repeat/"]),
        "route_following": (paper_headline(region, _read(inputs, "follow"), "Success rate", "agent (localization)",
                                           inputs["follow"]),
                            {"table": inputs["follow"], **{k: inputs[k] for k in inputs if k.startswith("controller_")}},
                            _read(inputs, "follow") + ("\n# Closed-loop check of the controllers trained here\n\n" + render(check)
                                                       if controllers else ""),
                            [f"results/{region}/drive/follow/paths.png", f"results/{region}/drive/follow/success.png",
                             f"results/{region}/drive/follow/strip.png"]),
        "pipeline": (pipeline_headline(region, jobs, _json(inputs, "graph_stats")), {"graph": inputs["graph_stats"]},
                     "# Every job with a benchmark file, its last run (`results/" + region + "/benchmarks/*.tsv`)\n\n"
                     + (render(job_table) if len(jobs) else "None found.\n"),
                     [f"results/{region}/graph/map.png", f"results/{region}/report.html"]),
    }
    headline = [f"# Headline tables: {region}", ""]
    for task, (rows, sources, body, figures) in made.items():
        write_text(outputs[task], page(task, region, rows, sources, body, reports[task], figures))
        headline += [f"## {TASKS[task]}", "", block(task, render(rows))]
    write_text(outputs["headline"], "\n".join(headline))
    return {"pages": float(len(made)), "reports_included": float(sum(map(len, reports.values())))}
