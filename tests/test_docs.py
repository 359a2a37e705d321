"""The docs site builds with `mkdocs build --strict` (so CI builds it), with and without generated results pages;
the config reference is generated from the schema, every key in it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from topoloc.config import schema
from topoloc.report.config_reference import config_reference, keys

REPO = Path(__file__).resolve().parents[1]


def build(site: Path, results: Path) -> subprocess.CompletedProcess:
    """``mkdocs build --strict`` of the repository into ``site``, reading results pages from ``results``."""
    env = {**os.environ, "TOPOLOC_RESULTS": str(results)}
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)


def test_the_site_builds_strict_without_results_pages(tmp_path):
    done = build(tmp_path / "site", tmp_path / "no-results")
    assert done.returncode == 0, done.stderr
    reference = (tmp_path / "site" / "reference" / "config" / "index.html").read_text()
    assert "localization.evaluate.start_every_m" in reference and "odometry.drives.&lt;name&gt;.poses" in reference
    assert "This build found none" in (tmp_path / "site" / "results" / "index.html").read_text()
    assert (tmp_path / "site" / "changelog" / "index.html").is_file()


def test_the_site_builds_strict_with_results_pages(tmp_path):
    pages = tmp_path / "results" / "tinyregion" / "pages"
    pages.mkdir(parents=True)
    (pages / "localization.md").write_text("# Localization: tinyregion\n\n| region | median (m) |\n|---|---|\n| tinyregion | 123 |\n")
    (pages / "headline.md").write_text("# Headline tables: tinyregion\n")
    done = build(tmp_path / "site", tmp_path / "results")
    assert done.returncode == 0, done.stderr
    page = (tmp_path / "site" / "results" / "tinyregion" / "localization" / "index.html").read_text()
    assert "<td>123</td>" in page
    assert "tinyregion" in (tmp_path / "site" / "index.html").read_text()  # in the nav
    assert not (tmp_path / "site" / "results" / "tinyregion" / "headline").exists()


def test_the_config_reference_lists_every_key_with_its_default():
    text = config_reference()
    tree = schema()
    listed = [key for key, _, _ in keys(tree)]
    assert len(listed) == len(set(listed)) > 300
    for key, node, required in keys(tree):
        if "properties" in node and key.count(".") == 0:
            continue  # a section: its description heads its table
        row = next(line for line in text.splitlines() if line.startswith(f"| `{key}` |"))
        if "default" in node and not isinstance(node["default"], dict):
            assert "`" in row.split("|")[3], row
    assert "| `region.name` | string | required |" in text


@pytest.mark.parametrize("path", ["README.md", "CHANGELOG.md", "docs/architecture.md"])
def test_no_run_logs_in_the_guides(path):
    text = (REPO / path).read_text()
    assert "load average" not in text and " UTC" not in text
