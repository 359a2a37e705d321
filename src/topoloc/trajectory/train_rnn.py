"""Stage ``train_rnn``: fit the trajectory RNN on the DFS dataset with Lightning.

Trained by :func:`topoloc.training.fit` (the training path shared with
``train_retrieval``): metrics ``train/loss``, ``val/loss``, ``val/acc``,
``val/acc_last`` (and ``val/state_loss`` with the auxiliary heads) go to the
stage's MLflow run; the best checkpoint (lowest ``val/loss``) is written to
``model`` and logged as an MLflow PyTorch model with its signature.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from topoloc.io import atomic_path, write_json
from topoloc.trajectory.fitting import fit
from topoloc.trajectory.model import log_checkpoint

log = logging.getLogger(__name__)


def mlflow_active() -> bool:
    """Whether an MLflow run is active (the stage's)."""
    import mlflow

    return mlflow.active_run() is not None


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train on ``inputs`` train/val/stats; write ``model``, ``history`` and ``metrics``."""
    stats = json.loads(Path(inputs["stats"]).read_text())
    _, history, metrics = fit(conf, inputs["train"], inputs["val"], int(stats["classes"]), outputs["model"],
                              log_model=conf["train"]["log_model"], feature_dim=int(stats.get("feature_dim", 0)))
    if conf["train"]["log_model"] and mlflow_active():
        log_checkpoint(outputs["model"])
    with atomic_path(outputs["history"]) as tmp:
        history.to_csv(tmp, index=False)
    write_json(outputs["metrics"], metrics)
    log.info("trained: %s", metrics)
    return metrics
