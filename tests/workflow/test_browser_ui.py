"""The pipeline's reports in headless chromium: a small tracked run (download_osm, build_graph) in a scratch copy,
its Snakemake report opened, and the MLflow UI served over its store (``mlflow ui`` on a free port, started and
stopped here): the stage runs nested under the pipeline run, a metric chart, a figure artifact, the logged model.

The UI is a React app: the test waits for its elements; the REST API only cross-checks what the UI shows. The model
is logged by a tracked run of this test (a real training stage takes minutes), with the stage glue's
:class:`topoloc.tracking.StageRun` like every stage.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import urllib.request

import pytest
from tests.workflow.conftest import clean_env, free_port, wait_for_http

from topoloc.viewer.browser import chromium_missing, console_errors, start_chromium

pytestmark = [pytest.mark.slow, pytest.mark.browser]

GRAPH = "results/helsinki/graph/graph.graphml"


def _log_a_model(root) -> str:
    """A tracked run with a loss curve and a small logged PyTorch model, in the store of ``root``; its run id."""
    script = (
        "import os, mlflow, numpy as np, torch\n"
        "from topoloc import tracking\n"
        "os.environ[tracking.INVOCATION_ENV] = tracking.new_invocation_id()\n"
        "tags = {'mlflow.runName': 'train_tiny region=helsinki', 'topoloc.wildcards.region': 'helsinki'}\n"
        "with tracking.StageRun('topoloc', 'train_tiny', tags, {'hidden': 2}) as run:\n"
        "    for step in range(6):\n"
        "        mlflow.log_metric('train/loss', 1.0 / (step + 1), step=step)\n"
        "    mlflow.pytorch.log_model(torch.nn.Linear(2, 1), name='model', pip_requirements=['torch'],\n"
        "                             input_example=np.zeros((2, 2), np.float32))\n"
        "tracking.finish_invocation(os.environ[tracking.INVOCATION_ENV], 'FINISHED')\n"
        "print(run.run_id)\n")
    proc = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, env=clean_env(), check=False)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip().splitlines()[-1]


def _rest(base: str, path: str, body: dict | None = None) -> dict:
    """A call of the tracking server's REST API (POST with ``body``, else GET)."""
    data = json.dumps(body).encode() if body is not None else None
    request = urllib.request.Request(f"{base}/ajax-api/2.0/mlflow/{path}", data=data,
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as response:
        return json.loads(response.read())


@pytest.fixture()
def mlflow_ui(workflow):
    """The workflow copy after a small tracked run, and the base URL of ``mlflow ui`` over its store."""
    reason = chromium_missing()
    if reason:
        pytest.skip(reason)
    workflow.run(GRAPH, "--cores", "2")
    port = free_port()  # the server starts while the report is built and the model logged (it reads the store live)
    server = subprocess.Popen([sys.executable, "-m", "mlflow", "ui", "--backend-store-uri", "sqlite:///results/mlflow.db",
                               "--host", "127.0.0.1", "--port", str(port), "--workers", "1"], cwd=workflow.root,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=clean_env(), start_new_session=True)
    base = f"http://127.0.0.1:{port}"
    try:
        workflow.run("--report", "report.html", GRAPH)
        model_run = _log_a_model(workflow.root)
        wait_for_http(f"{base}/health", server, "mlflow ui")
        yield workflow.root, base, model_run
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=30)


def test_the_report_and_the_mlflow_ui_show_the_runs(mlflow_ui):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    root, base, model_run = mlflow_ui
    driver = start_chromium(1600, 1000)
    try:
        wait = WebDriverWait(driver, 60)
        # the Snakemake report opens and lists the road graph's figure
        driver.get((root / "report.html").as_uri())
        wait.until(lambda d: "Results" in d.find_element(By.TAG_NAME, "body").text)
        driver.find_element(By.XPATH, "//*[normalize-space(text())='Results']").click()
        wait.until(lambda d: "Road graph" in d.find_element(By.TAG_NAME, "body").text)
        driver.find_element(By.XPATH, "//*[normalize-space(text())='Road graph']").click()
        wait.until(lambda d: "map" in d.find_element(By.TAG_NAME, "body").text.split())  # the figure's label
        assert console_errors(driver) == []

        experiment = _rest(base, "experiments/get-by-name?experiment_name=topoloc")["experiment"]["experiment_id"]
        runs = _rest(base, "runs/search", {"experiment_ids": [experiment]})
        by_name = {r["info"]["run_name"]: r for r in runs["runs"]}
        stage = by_name["build_graph region=helsinki"]
        parent_id = next(t["value"] for t in stage["data"]["tags"] if t["key"] == "mlflow.parentRunId")
        parent_name = next(r["info"]["run_name"] for r in runs["runs"] if r["info"]["run_id"] == parent_id)

        # the runs table: the pipeline run, and its stage runs once expanded
        driver.get(f"{base}/#/experiments/{experiment}/runs")
        link = wait.until(lambda d: d.find_element(By.XPATH, f"//a[contains(., '{parent_name}')]"))
        assert not driver.find_elements(By.XPATH, "//a[contains(., 'build_graph region=helsinki')]")  # nested: hidden
        link.find_element(By.XPATH, "./ancestor::*[@role='row'][1]").find_element(By.TAG_NAME, "button").click()
        wait.until(lambda d: {"build_graph region=helsinki", "download_osm region=helsinki"}
                   <= {a.text for a in d.find_elements(By.XPATH, "//a[contains(., 'region=helsinki')]")})

        # a metric chart of the tracked training run
        driver.get(f"{base}/#/experiments/{experiment}/runs/{model_run}/model-metrics")
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, ".js-plotly-plot")
                   and "train/loss" in d.find_element(By.TAG_NAME, "body").text)

        # the road graph's figure, shown as an image
        stage_id = stage["info"]["run_id"]
        driver.get(f"{base}/#/experiments/{experiment}/runs/{stage_id}/artifacts/map.png")
        wait.until(lambda d: any((img.get_attribute("src") or "").startswith(("blob:", "data:image/png"))
                                 for img in d.find_elements(By.TAG_NAME, "img")))

        # the logged model, with the run that logged it
        driver.get(f"{base}/#/experiments/{experiment}/models")
        wait.until(lambda d: "train_tiny region=helsinki" in d.find_element(By.TAG_NAME, "body").text)
        assert driver.find_elements(By.XPATH, "//*[normalize-space(text())='model']")
    finally:
        driver.quit()
