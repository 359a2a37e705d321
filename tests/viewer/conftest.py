"""Fixtures of the viewer tests: a small written viewer, and headless chromium (skipped, with the reason, when absent)."""

from __future__ import annotations

import pytest
from viewer_helpers import write_repeat_inputs, write_small_viewer

from topoloc.viewer.browser import chromium_missing, start_chromium


@pytest.fixture(scope="session")
def small_viewer(tmp_path_factory):
    """(path, data, graph, true track) of the small viewer."""
    path = tmp_path_factory.mktemp("viewer") / "drive.html"
    data, graph, xy = write_small_viewer(path)
    return path, data, graph, xy


@pytest.fixture()
def repeat_inputs(tmp_path):
    """The teach-and-repeat viewer's inputs (:func:`viewer_helpers.write_repeat_inputs`), by name."""
    return write_repeat_inputs(tmp_path)


@pytest.fixture(scope="session")
def browser():
    """Headless chromium through Selenium; skipped with the reason when chromium, its driver or selenium is absent."""
    reason = chromium_missing()
    if reason:
        pytest.skip(reason)
    driver = start_chromium()
    try:
        yield driver
    finally:
        driver.quit()
