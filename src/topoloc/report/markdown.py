"""Markdown tables read from the stages' outputs, and the README's headline tables refreshed from the results pages.

The results pages stage (:mod:`topoloc.report.write_results_pages`) writes ``results/{region}/pages/headline.md``:
one table per task between marker comments (:data:`MARKER`). ``python -m topoloc.report.markdown`` puts them into
the README between the same markers, the rows of every region in one table, so the README's figures are never typed.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from pathlib import Path

from topoloc.errors import InputError
from topoloc.report_tables import markdown_table

#: The comments around a task's headline table, in headline.md and in the README.
MARKER = ("<!-- headline:{task} -->", "<!-- /headline:{task} -->")
_BLOCK = re.compile(r"<!-- headline:(?P<task>[a-z_]+) -->\n(?P<body>.*?)<!-- /headline:(?P=task) -->", re.S)

Row = list[str]


def cells(line: str) -> Row:
    """The cells of one markdown table line (``| a | b |`` -> ``['a', 'b']``)."""
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def tables(text: str) -> list[tuple[str, list[Row]]]:
    """Every table of ``text`` with the heading above it: (heading, rows), the header row first, separators dropped."""
    found: list[tuple[str, list[Row]]] = []
    heading, rows = "", []
    for line in [*text.splitlines(), ""]:
        if line.lstrip().startswith("|"):
            if not re.fullmatch(r"\|?\s*:?-+:?\s*(\|\s*:?-+:?\s*)*\|?", line.strip()):
                rows.append(cells(line))
            continue
        if rows:
            found.append((heading, rows))
            rows = []
        if line.startswith("#"):
            heading = line.lstrip("#").strip()
    return found


def table_under(text: str, heading: str, where: str) -> list[Row]:
    """The first table whose heading starts with ``heading`` ("" for the first table); ``where`` names the file."""
    for title, rows in tables(text):
        if title.startswith(heading):
            return rows
    raise InputError(where, f"no table under a heading '{heading}...'")


def render(rows: Sequence[Row]) -> str:
    """A markdown table of ``rows`` (the header first)."""
    head, *body = rows
    return markdown_table(head, body) + "\n"


def demote(text: str, levels: int = 1) -> str:
    """``text`` with every markdown heading ``levels`` deeper (an included file's ``#`` becomes ``##``)."""
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m.group(1)) + levels) + " ", text, flags=re.M)


def block(task: str, body: str) -> str:
    """``body`` between the markers of ``task``."""
    start, end = (m.format(task=task) for m in MARKER)
    return f"{start}\n{body.rstrip()}\n{end}\n"


def blocks(text: str) -> dict[str, str]:
    """Task -> the text between its markers in ``text``."""
    return {m.group("task"): m.group("body") for m in _BLOCK.finditer(text)}


def merge(bodies: Sequence[str]) -> str:
    """One table of the tables in ``bodies`` that share a header (rows in order); other headers follow as tables."""
    merged: dict[tuple[str, ...], list[Row]] = {}
    for body in bodies:
        for _, rows in tables(body):
            merged.setdefault(tuple(rows[0]), [rows[0]]).extend(rows[1:])
    return "\n".join(render(rows) for rows in merged.values())


def refresh(readme: str, headlines: Sequence[str]) -> tuple[str, list[str]]:
    """``readme`` with each marked table replaced by the merged tables of ``headlines``; and the tasks replaced.
    A task that no headline has keeps what the README holds."""
    found: dict[str, list[str]] = {}
    for text in headlines:
        for task, body in blocks(text).items():
            found.setdefault(task, []).append(body)
    replaced: list[str] = []

    def _replace(match: re.Match[str]) -> str:
        task = match.group("task")
        if task not in found:
            return match.group(0)
        replaced.append(task)
        return block(task, merge(found[task])).rstrip("\n")

    return _BLOCK.sub(_replace, readme), replaced


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m topoloc.report.markdown [--readme README.md] [HEADLINE.md ...]``: refresh the README's tables."""
    parser = argparse.ArgumentParser(prog="python -m topoloc.report.markdown", description=main.__doc__)
    parser.add_argument("headlines", nargs="*", type=Path,
                        help="headline files, in the order of the rows (default: results/*/pages/headline.md)")
    parser.add_argument("--readme", type=Path, default=Path("README.md"))
    args = parser.parse_args(argv)
    paths = args.headlines or sorted(Path("results").glob("*/pages/headline.md"))
    if not paths:
        print("topoloc: results/*/pages/headline.md: none found; run `snakemake all` first", file=sys.stderr)
        return 1
    text, replaced = refresh(args.readme.read_text(), [path.read_text() for path in paths])
    args.readme.write_text(text)
    print(f"{args.readme}: tables {', '.join(replaced) or 'none'} from {', '.join(map(str, paths))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
