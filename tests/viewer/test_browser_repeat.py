"""The teach-and-repeat viewer in headless chromium: a closed-loop drive is picked in the selector, and the slider
moves its vehicle to the trace's coordinates (by progress along the route), up to where the drive stopped."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from viewer_helpers import EPISODES, embedded

from topoloc.config import load
from topoloc.graph.road_graph import RoadGraph
from topoloc.viewer.browser import console_errors, open_viewer
from topoloc.viewer.page import latlon_of
from topoloc.viewer.view_repeat import run

pytestmark = pytest.mark.browser
VIEW = "return window.topolocViewer"


def expected_at(trace: pd.DataFrame, driven_m: float, start_m: float, latlon) -> list[float] | None:
    """Where the vehicle of ``trace`` should be when the repeat drive has driven ``driven_m``: its last point whose
    progress (route start + s_m) is no further (None: its route has not started yet)."""
    reached = trace[start_m + trace.s_m <= driven_m + 1e-9]
    return None if reached.empty else latlon(reached[["x", "y"]].to_numpy()[-1:])[0]


def test_the_slider_moves_the_closed_loop_vehicle_along_its_trace(browser, repeat_inputs, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import Select

    path = tmp_path / "repeat.html"
    run({"viewer": load(None, {"viewer": {"condition": "night"}})["viewer"], "region": "test"}, repeat_inputs,
        {"html": str(path)})
    driven = embedded(path)["time"]["driven_m"]
    latlon = latlon_of(RoadGraph.load(repeat_inputs["graph"]).crs)
    traces = pd.read_csv(repeat_inputs["traces"])
    browser.get_log("browser")
    open_viewer(browser, path)
    assert console_errors(browser) == []
    pick = Select(browser.find_element(By.ID, "tl-drive"))
    assert [o.text for o in pick.options] == ["Topo-LP (ground truth), route 0, repeat 0: success after 400 m",
                                              "replay (place_loop), route 0, repeat 0: off_road after 150 m"]
    pick.select_by_index(1)
    assert browser.execute_script(f"{VIEW}.driveKey()") == EPISODES[1]
    failed = traces[traces.episode == EPISODES[1]]
    slider = browser.find_element(By.ID, "tl-slider")
    slider.send_keys(Keys.HOME)
    assert browser.execute_script(f"{VIEW}.driveLatLng()") is None  # the route starts 100 m into the repeat drive
    seen = []
    for _ in range(6):
        for _ in range(6):
            slider.send_keys(Keys.ARROW_RIGHT)
        row = browser.execute_script(f"{VIEW}.row()")
        want = expected_at(failed, driven[row], 100.0, latlon)
        got = browser.execute_script(f"{VIEW}.driveLatLng()")
        assert (got is None) == (want is None) and (want is None or got == pytest.approx(want, abs=1e-6)), row
        if got is not None:
            seen.append(tuple(got))
    assert len(set(seen)) >= 3  # it moved
    slider.send_keys(Keys.END)
    stop = latlon(failed[["x", "y"]].to_numpy()[-1:])[0]
    assert browser.execute_script(f"{VIEW}.driveLatLng()") == pytest.approx(stop, abs=1e-6)  # where it went off the road
    text = browser.execute_script(f"{VIEW}.driveText()")
    assert text.endswith("(stopped)") and "command" in text and "off_road after 150 m" in text
    tooltip = browser.find_element(By.CSS_SELECTOR, ".tl-command").text
    assert tooltip == f"command {failed.command.iat[-1]} (vertex {failed.vertex.iat[-1]})"
    pick.select_by_index(0)  # the other drive, at the same moment: its own trace, which goes on past the repeat
    success = traces[traces.episode == EPISODES[0]]  # drive's end (500 m), so the last row shows where it ended
    want = latlon(success[["x", "y"]].to_numpy()[-1:])[0]
    assert browser.execute_script(f"{VIEW}.driveLatLng()") == pytest.approx(want, abs=1e-6)
    assert not np.allclose(want, stop)
    slider.send_keys(Keys.ARROW_LEFT)
    row = browser.execute_script(f"{VIEW}.row()")
    assert browser.execute_script(f"{VIEW}.driveLatLng()") == pytest.approx(
        expected_at(success, driven[row], 100.0, latlon), abs=1e-6)
    assert console_errors(browser) == []
