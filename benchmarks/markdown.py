"""What every benchmark shares: its printed figures, also written as markdown to ``results/benchmarks/<name>.md``;
its seed lists."""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

from topoloc.io import write_text

REPO = Path(__file__).resolve().parents[1]
OUT_DIR = Path("results") / "benchmarks"


def add_out_option(parser: argparse.ArgumentParser, name: str) -> None:
    """``--out``: the markdown file the benchmark ``name`` writes its printed figures to."""
    parser.add_argument("--out", type=Path, default=OUT_DIR / f"{name}.md",
                        help="markdown copy of the printed figures (default: %(default)s)")


def seed_list(text: str) -> list[int]:
    """The ``type`` of a seed-list option (``--seeds 0,1,2``): comma-separated integers, at least one, none twice."""
    try:
        seeds = [int(s) for s in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of integers") from None
    if len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"{text!r} names a seed twice")
    return seeds


class _Tee(io.TextIOBase):
    """A text stream writing to two streams."""

    def __init__(self, first: TextIO, second: TextIO) -> None:
        self.first, self.second = first, second

    def write(self, text: str) -> int:
        self.first.write(text)
        self.second.write(text)
        return len(text)

    def flush(self) -> None:
        self.first.flush()


@contextlib.contextmanager
def markdown_copy(path: str | Path) -> Iterator[None]:
    """Everything printed inside the block goes to stdout as before and, when the block ends without error, to
    ``path`` (written atomically: a failed benchmark leaves the previous file)."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(_Tee(sys.stdout, buffer)):
        yield
    write_text(path, buffer.getvalue())
