"""The aggregate of an experiment: one markdown section (heading, a sentence on what was run, one table with each
job's figures and their mean and spread) and the same figures as JSON."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from topoloc.io import write_json, write_text


def mean_and_spread(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation of the finite ``values`` (NaN when there are none; spread 0 for one)."""
    finite = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    if not len(finite):
        return math.nan, math.nan
    return float(finite.mean()), float(finite.std(ddof=1)) if len(finite) > 1 else 0.0


def spread_rows(jobs: pd.DataFrame, over: str, keys: list[str], figures: list[str]) -> pd.DataFrame:
    """The rows of ``jobs`` (one per job ``over`` and ``keys``), then per ``keys`` group of several jobs a row
    ``over = "mean ± sd"`` whose cells are "mean ± sd" of the jobs' finite figures (the value alone when one is)."""
    rows = []
    groups = jobs.groupby(keys, sort=False) if keys else [((), jobs)]
    for key, group in groups:
        key = key if isinstance(key, tuple) else (key,)
        for row in group.itertuples(index=False):
            rows.append({**dict(zip(keys, key)), over: getattr(row, over),
                         **{f: _cell(getattr(row, f)) for f in figures}})
        if len(group) > 1:
            rows.append({**dict(zip(keys, key)), over: f"**mean ± sd** ({len(group)})",
                         **{f: _spread_cell(group[f].tolist()) for f in figures}})
    return pd.DataFrame(rows)


def spread_json(jobs: pd.DataFrame, over: str, keys: list[str], figures: list[str]) -> list[dict[str, Any]]:
    """Per ``keys`` group: its keys, the jobs ``over`` it, and the mean and spread of each figure."""
    out = []
    groups = jobs.groupby(keys, sort=False) if keys else [((), jobs)]
    for key, group in groups:
        key = key if isinstance(key, tuple) else (key,)
        stats = {f: mean_and_spread(group[f].tolist()) for f in figures}
        out.append({**dict(zip(keys, key)), over: [str(v) for v in group[over]],
                    "mean": {f: m for f, (m, _) in stats.items()}, "sd": {f: s for f, (_, s) in stats.items()}})
    return out


def write_summary(outputs: dict[str, str], title: str, sentence: str, jobs: pd.DataFrame, over: str, keys: list[str],
                  figures: list[str]) -> None:
    """``outputs['summary']`` (markdown) and ``outputs['json']`` of the jobs' figures."""
    table = spread_rows(jobs, over, keys, figures).to_markdown(index=False, disable_numparse=True)  # cells: .3f text
    write_text(outputs["summary"], f"## {title}\n\n{sentence}\n\n{table}\n")
    records = json.loads(jobs.to_json(orient="records"))  # NaN -> null
    write_json(outputs["json"], {"title": title, "over": over, "jobs": records,
                                 "groups": _finite(spread_json(jobs, over, keys, figures))})


def _spread_cell(values: Sequence[float]) -> str:
    finite = [v for v in values if v is not None and np.isfinite(v)]
    mean, sd = mean_and_spread(finite)
    return "" if not finite else f"{mean:.3f}" if len(finite) == 1 else f"{mean:.3f} ± {sd:.3f}"


def _cell(value: Any) -> str:
    if isinstance(value, float | np.floating):
        return "" if not np.isfinite(value) else f"{value:.3f}"
    return str(value)


def _finite(data: Any) -> Any:
    """``data`` with NaN and infinities as None (JSON has neither)."""
    if isinstance(data, dict):
        return {k: _finite(v) for k, v in data.items()}
    if isinstance(data, list):
        return [_finite(v) for v in data]
    if isinstance(data, float) and not math.isfinite(data):
        return None
    return data
