"""A trained controller's steering against the expert's labels on its own demonstrations, by how hard the expert steers.

Usage (after ``train_controller`` built ``results/<region>/drive/<agent>/controller.ckpt``)::

    PYTHONPATH=src python benchmarks/offline_steer.py --agent lp [--config config/config.yaml]
        [--also config/drive_paper.yaml] [--controller CKPT] [--steps 600]

Open loop: the controller sees the recorded steps (image, speed, and the command or the local-path image without
the training noise), as in training. For the validation routes (the last
``drive.demonstrations.val_routes``) and the training routes of ``results/<region>/drive/demonstrations.npz`` it draws ``--steps`` steps with |label| > 0.5
and as many with less (seeded), and prints per bin of |label|: the steps, the mean absolute error, the median ratio
of the controller's steering to the label and the share with the label's sign. Ratios near 1 with the right sign
where the closed-loop check fails (``check_failures.py``) mean the failures come from states the demonstrations do
not hold, not from a fit the network missed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
import yaml

from topoloc.config import deep_merge, load
from topoloc.drive.controller import load_controller
from topoloc.drive.demonstrations import Demonstrations
from topoloc.drive.local_path import lane_frame_path, raster
from topoloc.drive.topo_lp import CONTROLLERS

BINS = [(0.0, 0.1), (0.1, 0.3), (0.3, 0.5), (0.5, 0.8), (0.8, 1.01)]


def predictions(model: torch.nn.Module, agent: str, demos: Demonstrations, idx: np.ndarray) -> np.ndarray:
    """The controller's steering on the recorded steps ``idx``."""
    out = []
    for k in idx:
        told = raster(lane_frame_path(demos.path[k])) if agent == "lp" else int(demos.command[k])
        out.append(model.act(demos.images[k], float(demos.speed[k]), told)[0])
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", choices=sorted(CONTROLLERS), default="lp")
    parser.add_argument("--config", default="config/config.yaml")
    parser.add_argument("--also", nargs="*", default=[], help="config files merged over --config (later ones win)")
    parser.add_argument("--controller", type=Path, help="checkpoint (default: the region's own)")
    parser.add_argument("--steps", type=int, default=600, help="steps drawn per half (hard, easy) and set")
    args = parser.parse_args()
    torch.set_num_threads(1)
    extra: dict = {}
    for path in args.also:
        extra = deep_merge(extra, yaml.safe_load(Path(path).read_text()) or {})
    conf = load(Path(args.config), overrides=extra)
    root = Path("results") / conf["region"]["name"] / "drive"
    demos = Demonstrations.load(root / "demonstrations.npz")
    val_routes = int(conf["drive"]["demonstrations"]["val_routes"])
    model = load_controller(args.controller or root / args.agent / "controller.ckpt", cls=CONTROLLERS[args.agent]).eval()
    routes = np.unique(demos.route)
    val = np.isin(demos.route, routes[len(routes) - val_routes:])
    rng = np.random.default_rng(0)
    print("| routes | |label| | steps | MAE | median steer / label | same sign |")
    print("|---|---|---|---|---|---|")
    for name, idx in (("validation", np.flatnonzero(val)), ("training", np.flatnonzero(~val))):
        hard = np.abs(demos.steer[idx]) > 0.5
        pick = np.concatenate([rng.choice(idx[hard], min(args.steps, int(hard.sum())), replace=False),
                               rng.choice(idx[~hard], min(args.steps, int((~hard).sum())), replace=False)])
        pred, label = predictions(model, args.agent, demos, pick), demos.steer[pick]
        for lo, hi in BINS:
            m = (np.abs(label) >= lo) & (np.abs(label) < hi)
            if m.any():
                ratio = f"{np.median(pred[m] / label[m]):.2f}" if lo > 0 else "-"
                print(f"| {name} | {lo}-{min(hi, 1.0)} | {int(m.sum())} | {np.abs(pred[m] - label[m]).mean():.3f} | "
                      f"{ratio} | {np.mean(np.sign(pred[m]) == np.sign(label[m])):.2f} |")


if __name__ == "__main__":
    main()
