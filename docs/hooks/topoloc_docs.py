"""mkdocs hooks of the topoloc docs site (registered in mkdocs.yml).

* The config reference (``reference/config.md``) is generated from ``src/topoloc/config.schema.yaml`` at every build.
* The results pages that the rule ``write_results_pages`` wrote (``results/*/pages/*.md``) are added under "Results",
  one section per region; ``TOPOLOC_RESULTS`` names another results folder. Without them the tracked
  ``docs/results/index.md`` says how to make them, and the site builds as well (``mkdocs build --strict``).
* ``diagnostics.md`` joins the Reference section when it exists (the benchmarks' diagnostics page).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

from topoloc.report.config_reference import config_reference
from topoloc.report.write_results_pages import TASKS  # task (page file name) -> title, in the order of the nav

REPO = Path(__file__).resolve().parents[2]


def results_pages() -> dict[str, list[Path]]:
    """Region -> its generated pages, in the order of :data:`TASKS` (``headline.md`` is the README's, not a page)."""
    root = Path(os.environ.get("TOPOLOC_RESULTS", REPO / "results"))
    found = {}
    for folder in sorted(root.glob("*/pages")):
        pages = [folder / f"{task}.md" for task in TASKS if (folder / f"{task}.md").is_file()]
        if pages:
            found[folder.parent.name] = pages
    return found


def _section(nav: list[Any], title: str) -> list[Any]:
    for item in nav:
        if isinstance(item, dict) and title in item:
            return item[title]
    raise KeyError(f"mkdocs.yml: nav has no section {title!r}")


def on_config(config: Any) -> Any:
    """Nav entries for the results pages found and, when it exists, the diagnostics page."""
    results = _section(config.nav, "Results")
    for region, pages in results_pages().items():
        results.append({region: [{TASKS[page.stem]: f"results/{region}/{page.name}"} for page in pages]})
    if (Path(config.docs_dir) / "diagnostics.md").is_file():
        _section(config.nav, "Reference").append({"Diagnostics": "diagnostics.md"})
    return config


def on_files(files: Files, config: Any) -> Files:
    """Add the generated config reference, the changelog and the results pages to the site's files."""
    files.append(File.generated(config, "reference/config.md", content=config_reference()))
    files.append(File.generated(config, "changelog.md", abs_src_path=str(REPO / "CHANGELOG.md")))
    for region, pages in results_pages().items():
        for page in pages:
            files.append(File.generated(config, f"results/{region}/{page.name}", abs_src_path=str(page)))
    return files
