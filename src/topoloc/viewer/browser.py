"""Headless chromium for the viewer's browser tests and its benchmark (Selenium and the system chromium;
``apt-get install chromium chromium-driver``, ``pip install selenium``)."""

from __future__ import annotations

import importlib.util
import shutil
import time
from pathlib import Path
from typing import Any


def chromium_paths() -> tuple[str | None, str | None]:
    """The chromium binary and its driver on the PATH (None where absent)."""
    return shutil.which("chromium") or shutil.which("chromium-browser"), shutil.which("chromedriver")


def chromium_missing() -> str | None:
    """Why headless chromium cannot be driven here, or None when it can."""
    if importlib.util.find_spec("selenium") is None:
        return "selenium is not installed (pip install -e '.[test]')"
    binary, driver = chromium_paths()
    if not binary or not driver:
        return "chromium / chromedriver are not installed (apt-get install chromium chromium-driver)"
    return None


def start_chromium(width: int = 1400, height: int = 900) -> Any:
    """A headless chromium WebDriver that keeps the page's console log (``driver.get_log('browser')``)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    binary, driver_path = chromium_paths()
    if not binary or not driver_path:
        raise RuntimeError(chromium_missing())
    options = Options()
    options.binary_location = binary
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", f"--window-size={width},{height}"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    driver.set_page_load_timeout(120)
    return driver


def open_viewer(driver: Any, path: str | Path, timeout: float = 60.0) -> float:
    """Load a viewer file and wait until its script has drawn the first moment; the seconds it took."""
    from selenium.webdriver.support.ui import WebDriverWait

    began = time.perf_counter()
    driver.get(Path(path).resolve().as_uri())
    WebDriverWait(driver, timeout).until(
        lambda d: d.execute_script("return document.body.getAttribute('data-topoloc-ready')") == "1")
    return time.perf_counter() - began


def console_errors(driver: Any) -> list[str]:
    """The page's console messages of level SEVERE (errors) since the last call."""
    return [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
