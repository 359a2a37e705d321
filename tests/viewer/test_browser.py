"""The viewer in headless chromium: it loads without console errors, the slider moves the markers and the belief,
a localizer can be switched off, the chart jumps the slider, playback runs."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from viewer_helpers import embedded

from topoloc.viewer.browser import console_errors, open_viewer

pytestmark = pytest.mark.browser


def _last(idx, row):
    return max(k for k, r in enumerate(idx) if r <= row)


@pytest.fixture()
def page(browser, small_viewer):
    path = small_viewer[0]
    browser.get_log("browser")  # drop earlier pages' messages
    open_viewer(browser, path)
    return browser, embedded(path)


def test_loads_without_console_errors_and_the_slider_moves_marker_and_belief(page):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    driver, blob = page
    assert console_errors(driver) == []
    view = "return window.topolocViewer"
    slider = driver.find_element(By.ID, "tl-slider")
    slider.send_keys(Keys.HOME)
    assert driver.execute_script(f"{view}.row()") == 0
    assert driver.execute_script(f"{view}.truthLatLng()") == pytest.approx(blob["truth"][0])
    first = blob["belief"]["idx"][0]  # the first stored belief: after the filter's first step
    assert first < 50
    for _ in range(first):
        slider.send_keys(Keys.ARROW_RIGHT)
    assert driver.execute_script(f"{view}.row()") == first
    start_belief, start_heat = driver.execute_script(f"{view}.beliefKey()"), driver.execute_script(f"{view}.heatPoints()")
    assert start_heat > 10
    slider.send_keys(Keys.END)
    last = len(blob["time"]["frame"]) - 1
    assert driver.execute_script(f"{view}.row()") == last
    assert driver.execute_script(f"{view}.truthLatLng()") == pytest.approx(blob["truth"][last])
    metric = blob["agents"][0]
    assert driver.execute_script(f"{view}.agentLatLng('metric')") == pytest.approx(metric["pos"][_last(metric["idx"], last)])
    assert driver.execute_script(f"{view}.beliefKey()") != start_belief
    assert driver.execute_script(f"{view}.heatPoints()") < start_heat
    items = driver.find_elements(By.CSS_SELECTOR, "#tl-belief li")
    assert len(items) >= 1 and items[0].text.startswith(("9", "100"))  # one road holds (nearly) all the belief
    for _ in range(5):
        slider.send_keys(Keys.ARROW_LEFT)
    assert driver.execute_script(f"{view}.row()") == last - 5
    assert driver.execute_script(f"{view}.truthLatLng()") == pytest.approx(blob["truth"][last - 5])
    assert console_errors(driver) == []


def test_a_localizer_can_be_switched_off(page):
    from selenium.webdriver.common.by import By

    driver, blob = page
    driver.execute_script("window.topolocViewer.setRow(window.topolocViewer.data.time.frame.length - 1)")
    labels = driver.find_elements(By.CSS_SELECTOR, ".leaflet-control-layers-overlays label")
    hmm = next(label for label in labels if "(hmm)" in label.text)
    assert driver.execute_script("return window.topolocViewer.visible('hmm')")
    hmm.find_element(By.TAG_NAME, "input").click()
    assert not driver.execute_script("return window.topolocViewer.visible('hmm')")
    assert driver.execute_script("return window.topolocViewer.agentLatLng('hmm')") is None
    assert driver.execute_script("return window.topolocViewer.visible('metric')")
    hmm.find_element(By.TAG_NAME, "input").click()
    assert driver.execute_script("return window.topolocViewer.agentLatLng('hmm')") is not None


def test_the_chart_jumps_the_slider_and_playback_runs(page):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    driver, blob = page
    chart = driver.find_element(By.ID, "tl-svg")
    width = chart.size["width"]
    ActionChains(driver).move_to_element_with_offset(chart, -int(width * 0.25), 0).click().perform()
    row = driver.execute_script("return window.topolocViewer.row()")
    driven = blob["time"]["driven_m"]
    assert 0.1 * driven[-1] < driven[row] < 0.4 * driven[-1]  # a quarter into the chart (offsets are from its centre): a quarter of the drive
    driver.find_element(By.ID, "tl-play").click()
    time.sleep(1.0)
    driver.find_element(By.ID, "tl-play").click()
    assert driver.execute_script("return window.topolocViewer.row()") > row
    assert console_errors(driver) == []


REPO = Path(__file__).resolve().parents[2]
REAL = [REPO / "results" / "kitti00" / "viewer" / "gt.html", REPO / "results" / "helsinki" / "viewer" / "ren00_clear_noon.html"]


def test_screenshot_of_a_real_viewer(browser, tmp_path):
    """The README's screenshot: a real drive's viewer while the belief collapses (set TOPOLOC_SCREENSHOT to a path,
    e.g. docs/images/viewer.png, to keep it). Skipped where the pipeline has not written a real viewer."""
    real = next((p for p in REAL if p.is_file()), None)
    if real is None:
        pytest.skip("no real viewer in results/ (run the pipeline: rule view_drive)")
    browser.get_log("browser")
    open_viewer(browser, real)
    blob = embedded(real)
    sure = [m["idx"] for m in blob["marks"] if m["kind"] == "sure"]
    row = int(0.8 * min(sure)) if sure else len(blob["time"]["frame"]) // 4
    browser.execute_script("window.topolocViewer.setRow(arguments[0]);"
                           "window.topolocViewer.map.setView(window.topolocViewer.truthLatLng(), 16);", row)
    time.sleep(0.5)
    out = Path(os.environ.get("TOPOLOC_SCREENSHOT", tmp_path / "viewer.png"))
    out.parent.mkdir(parents=True, exist_ok=True)
    assert browser.save_screenshot(str(out)) and out.stat().st_size > 20_000
    assert console_errors(browser) == []
