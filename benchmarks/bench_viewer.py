"""Viewer benchmark: file size, time to open and time to answer the slider in headless chromium.

Usage (after the pipeline wrote the viewers, rules ``view_drive`` / ``view_repeat`` / ``view_city``)::

    python -m benchmarks.bench_viewer [FILE.html ...] [--loads 3] [--moves 20]

Without files it measures every ``results/*/viewer/*.html`` and ``results/*/experiments/*/viewer/*.html``. Per
file: its size, the time from navigation until the viewer drew its first moment (median of ``--loads`` fresh
loads), and the time from a slider move (an ``input`` event at a random position) to the next painted frame
(median and worst of ``--moves`` moves). Needs chromium, chromedriver and selenium (see docs/viewer.md).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from benchmarks.markdown import add_out_option, markdown_copy

if TYPE_CHECKING:
    from selenium.webdriver.remote.webdriver import WebDriver

SLIDER_JS = """
const done = arguments[arguments.length - 1];
const slider = document.getElementById('tl-slider');
const began = performance.now();
slider.value = arguments[0];
slider.dispatchEvent(new Event('input'));
requestAnimationFrame(() => requestAnimationFrame(() => done(performance.now() - began)));
"""


def measure(driver: WebDriver, path: Path, loads: int, moves: int) -> dict[str, float]:
    """Size (MB), open time (s, median of ``loads``) and slider answer (ms, median and worst of ``moves``)."""
    import random

    from topoloc.viewer.browser import console_errors, open_viewer

    opened = []
    for _ in range(loads):
        driver.get("about:blank")
        opened.append(open_viewer(driver, path))
    rows = driver.execute_script("return window.topolocViewer.data.time.frame.length")
    rng = random.Random(0)
    answers = [driver.execute_async_script(SLIDER_JS, rng.randrange(rows)) for _ in range(moves)]
    errors = console_errors(driver)
    return {"size_mb": path.stat().st_size / 2**20, "open_s": statistics.median(opened), "rows": rows,
            "slider_ms": statistics.median(answers), "slider_worst_ms": max(answers), "console_errors": len(errors)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", type=Path, help="viewer HTML files (default: every results/*/viewer/*.html)")
    parser.add_argument("--loads", type=int, default=3, help="fresh loads per file (the median is reported)")
    parser.add_argument("--moves", type=int, default=20, help="slider moves per file")
    add_out_option(parser, "bench_viewer")
    args = parser.parse_args()
    from topoloc.viewer.browser import chromium_missing, start_chromium

    files = args.files or sorted(Path("results").glob("*/viewer/*.html")) + sorted(Path("results").glob("*/experiments/*/viewer/*.html"))
    if not files:
        sys.exit("bench_viewer: no viewer files (run the pipeline, or name them)")
    reason = chromium_missing()
    if reason:
        sys.exit(f"bench_viewer: {reason}")
    driver = start_chromium()
    try:
        with markdown_copy(args.out):
            print("## The viewer in headless chromium\n")
            print(f"Open: median of {args.loads} fresh loads until the first moment is drawn; slider: an input event "
                  f"at a random moment until the next painted frame, over {args.moves} moves.\n")
            print("| file | size MB | slider moments | open s | slider ms (median) | slider ms (worst) | console errors |")
            print("|---|---:|---:|---:|---:|---:|---:|")
            for path in files:
                m = measure(driver, path, args.loads, args.moves)
                print(f"| {path} | {m['size_mb']:.2f} | {m['rows']} | {m['open_s']:.2f} | {m['slider_ms']:.0f} | "
                      f"{m['slider_worst_ms']:.0f} | {m['console_errors']} |", flush=True)
    finally:
        driver.quit()


if __name__ == "__main__":
    main()
