"""Stage ``train_controller``: fit Topo-DLM (:mod:`topoloc.drive.controller`) or Topo-LP (:mod:`topoloc.drive.topo_lp`,
``conf["controller"]``: ``dlm`` or ``lp``) on the expert's demonstrations.

Data: the demonstrations of ``simulate_demonstrations`` (this region's, or those of the regions of
``drive.demonstrations_from`` pooled: a controller trained on several maps, checked on this one), split and drawn as
:mod:`topoloc.drive.controller_training` says. Trained by :func:`topoloc.drive.controller_training.fit` (the shared
Lightning path): the best checkpoint is written to ``model`` and logged to MLflow as a PyTorch model with its
signature (``(N, C + 2, H, W)`` -> ``(N, 2)``).
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


def load_demonstrations(conf: dict[str, Any], inputs: dict[str, str]) -> Demonstrations:
    """The demonstrations of ``inputs['demonstrations']``, or those of every input ``demonstrations_<map>`` (the
    regions of ``drive.demonstrations_from``) pooled (:meth:`Demonstrations.pool`). InputError naming the file whose
    images are not those of ``drive.camera`` and ``place.image``, or whose conditions differ from the first map's."""
    paths = [inputs["demonstrations"]] if "demonstrations" in inputs else \
        [path for name, path in inputs.items() if name.startswith("demonstrations_")]
    if not paths:
        raise InputError("drive.demonstrations_from", "no demonstrations to train on")
    want_h, want_w, want_c = image_shape(conf)
    maps = []
    for path in paths:
        demos = Demonstrations.load(path)
        h, w, c = demos.images.shape[1:]
        if (h, w, c) != (want_h, want_w, want_c):
            raise InputError(path, f"recorded with {w}x{h}x{c} images, but drive.camera and place.image give "
                             f"{want_w}x{want_h}x{want_c}: simulate the demonstrations again")
        if maps and demos.conditions != maps[0].conditions:
            raise InputError(path, f"recorded under {demos.conditions}, but {paths[0]} under {maps[0].conditions} "
                             "(drive.demonstrations.conditions must be the same in every region of "
                             "drive.demonstrations_from)")
        maps.append(demos)
    if len(maps) > 1:
        log.info("pooled the demonstrations of %d maps: %s", len(maps), {p: len(d) for p, d in zip(paths, maps)})
    return maps[0] if len(maps) == 1 else Demonstrations.pool(maps)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Train on ``inputs['demonstrations']`` (or the pooled ``demonstrations_<map>``: :func:`load_demonstrations`),
    then ``drive.dagger.rounds`` DAgger rounds on the training routes and the closed-loop check on
    ``drive.check.routes`` others (inputs ``osm``, ``graph``); write ``model``, ``history`` (with its ``round``),
    ``metrics`` (``check/...`` among them) and ``figure``."""
    drive = conf["drive"]
    demos = load_demonstrations(conf, inputs)
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
