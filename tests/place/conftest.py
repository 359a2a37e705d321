"""Fixtures of the place tests: the hand-made town of the render tests and config slices with small budgets."""

from __future__ import annotations

import copy
from pathlib import Path

from tests.render.conftest import render_conf, town  # noqa: F401 (the town fixture, re-exported)
from topoloc.config import load

REPO = Path(__file__).resolve().parents[2]
DEFAULTS = load(REPO / "config" / "config.yaml")["place"]


def place_conf(**sections) -> dict:
    """The default ``place`` slice (config/config.yaml, schema defaults filled) with small images and budgets, updated by ``sections``."""
    conf = copy.deepcopy(DEFAULTS)
    conf["image"].update(width=64, height=48)
    conf["train"].update(routes=3, val_routes=1, route_length_m=120.0, min_distance_m=20.0, min_frames=20,
                         batches_per_epoch=4, max_epochs=1, max_time_min=None, val_pairs=16, batch_size=8,
                         accelerator="cpu", log_model=False, log_every_n_steps=2)
    conf["network"].update(channels=[8, 16], embedding_dim=16, hidden=32)
    for key, value in sections.items():
        if isinstance(value, dict) and isinstance(conf.get(key), dict):
            conf[key].update(value)
        else:
            conf[key] = value
    return conf
