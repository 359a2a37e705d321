"""Markdown tables of the stages' reports: a plain table, and the paper's layout of a figure per condition."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import pandas as pd


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A markdown table: the ``header`` row, the separator, then one line per row of already formatted cells."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def condition_table(summary: pd.DataFrame, row_column: str, value_column: str, held_out: list[str], fmt: str,
                    row_header: str) -> str:
    """A markdown table like Cai & Wan's Tables 1 and 2: one row per value of ``row_column`` (in order of appearance,
    headed ``row_header``), its mean over the conditions, then one column per condition (those in ``held_out``
    marked) holding ``value_column`` formatted by ``fmt``; ``summary`` has one row per (row value, condition)."""
    conditions = list(dict.fromkeys(summary.condition))
    header = [row_header, "Mean", *[f"{c} (held out)" if c in held_out else c for c in conditions]]
    rows = []
    for name in dict.fromkeys(summary[row_column]):
        values = summary[summary[row_column] == name].set_index("condition").loc[conditions, value_column]
        rows.append([name, fmt.format(values.mean()), *[fmt.format(v) for v in values]])
    return markdown_table(header, rows)
