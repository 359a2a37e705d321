"""Stage ``train_controller``: fit Topo-DLM (:mod:`topoloc.drive.controller`) or Topo-LP (:mod:`topoloc.drive.topo_lp`,
``conf["controller"]``: ``dlm`` or ``lp``) on the expert's demonstrations.

Data: the demonstrations of ``simulate_demonstrations``, split and drawn as :mod:`topoloc.drive.controller_training`
says. Trained by :func:`topoloc.drive.controller_training.fit` (the shared Lightning path): the best checkpoint is written to
``model`` and logged to MLflow as a PyTorch model with its signature (``(N, C + 2, H, W)`` -> ``(N, 2)``).
Then ``drive.dagger.rounds`` DAgger rounds (:mod:`topoloc.drive.on_policy`): the controller drives the training routes
in the simulator (inputs ``osm`` and ``graph``), the expert labels the states it reached, and it trains on,
``dagger.epochs`` epochs a round; the model of the last round is written. Last, the closed-loop check
(``drive.check``): the controller alone drives routes it never saw; its success rate is in the metrics (``check/...``)
and the figure's title.
"""

from __future__ import annotations

import logging
from typing import Any

from topoloc.drive.camera import image_shape
from topoloc.drive.controller import AGENT_NAMES
from topoloc.drive.controller_training import check_controller, dagger_rounds, fit
from topoloc.drive.demonstrations import Demonstrations
from topoloc.drive.on_policy import DaggerSettings
from topoloc.drive.plot import training_figure
from topoloc.errors import InputError
from topoloc.io import atomic_path, write_json

log = logging.getLogger(__name__)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train on ``inputs['demonstrations']``, then ``drive.dagger.rounds`` DAgger rounds on the training routes and the
    closed-loop check on ``drive.check.routes`` others (inputs ``osm``, ``graph``); write ``model``, ``history`` (with
    its ``round``), ``metrics`` (``check/...`` among them) and ``figure``."""
    drive = conf["drive"]
    demos = Demonstrations.load(inputs["demonstrations"])
    (h, w, c), (want_h, want_w, want_c) = demos.images.shape[1:], image_shape(conf)
    if (h, w, c) != (want_h, want_w, want_c):
        raise InputError(inputs["demonstrations"], f"recorded with {w}x{h}x{c} images, but drive.camera and place.image "
                         f"give {want_w}x{want_h}x{want_c}: simulate the demonstrations again")
    agent = str(conf.get("controller", "dlm"))
    rounds = DaggerSettings.from_conf(drive["dagger"]).rounds if "dagger" in drive else 0
    log_model = bool(drive["train"]["log_model"])
    model, history, metrics = fit(drive, demos, outputs["model"], log_model=log_model and not rounds, agent=agent)
    if rounds:
        model, history, metrics = dagger_rounds(conf, inputs, outputs["model"], model, demos, history, metrics, log_model)
    if int(drive.get("check", {}).get("routes", 0)):
        metrics |= check_controller(conf, inputs, model)
        log.info("closed-loop check: %s", {k: v for k, v in metrics.items() if k.startswith("check/")})
    with atomic_path(outputs["history"]) as tmp:
        history.to_csv(tmp, index=False)
    write_json(outputs["metrics"], metrics)
    training_figure(history, outputs["figure"], AGENT_NAMES[agent], metrics)
    log.info("trained: %s", metrics)
    return metrics
