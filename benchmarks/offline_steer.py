"""A trained controller's steering against the expert's labels on its own demonstrations, by how hard the expert steers.

Usage (after ``train_controller`` built ``results/<region>/drive/<agent>/controller.ckpt``)::

    PYTHONPATH=src python benchmarks/offline_steer.py --agent lp [--config config/config.yaml]
        [--also config/experiments/drive_paper.yaml] [--controller CKPT] [--steps 600]

Open loop: the controller sees the recorded steps (image, speed, and the command or the local-path image without the
training noise), as in training. For the validation routes (the last ``drive.demonstrations.val_routes``) and the
training routes of ``results/<region>/drive/demonstrations.npz`` it draws ``--steps`` steps with |label| > 0.5 and as
many with less (seeded), and prints per bin of |label|: the steps, the mean absolute error, the median ratio of the
controller's steering to the label and the share with the label's sign. Ratios near 1 with the right sign where the
closed-loop check fails (``check_failures.py``) mean the failures come from states the demonstrations do not hold,
not from a fit the network missed. For Topo-LP also how much the local path moves the steering: on
``--steps`` validation steps, the mean change when each step gets the path image of a step on another validation
route, or a straight one.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from topoloc.config import load_layered
from topoloc.drive.controller import TopoDLM, load_controller
from topoloc.drive.demonstrations import Demonstrations
from topoloc.drive.local_path import lane_frame_path, path_plane
from topoloc.drive.topo_lp import CONTROLLERS

BINS = [(0.0, 0.1), (0.1, 0.3), (0.3, 0.5), (0.5, 0.8), (0.8, 1.01)]


def predictions(model: TopoDLM, agent: str, demos: Demonstrations, idx: np.ndarray,
                paths: np.ndarray | None = None) -> np.ndarray:
    """The controller's steering on the recorded steps ``idx`` (Topo-LP: with the local paths of the steps ``paths``,
    default their own)."""
    out = []
    for i, k in enumerate(idx):
        if agent == "lp":
            told = path_plane(lane_frame_path(demos.path[k if paths is None else paths[i]]))
        else:
            told = int(demos.command[k])
        out.append(model.act(demos.images[k], float(demos.speed[k]), told)[0])
    return np.array(out)


def path_effect(model: TopoDLM, demos: Demonstrations, idx: np.ndarray, rng: np.random.Generator) -> str:
    """How much Topo-LP's steering on steps ``idx`` moves with another step's local path, and with a straight one."""
    own = predictions(model, "lp", demos, idx)
    swap = np.array([rng.choice(idx[demos.route[idx] != demos.route[k]]) for k in idx])  # another route's step
    other = predictions(model, "lp", demos, idx, swap)
    straight = path_plane(lane_frame_path(np.column_stack([np.arange(1.0, 21.0), np.zeros(20)]).astype(np.float32)))
    flat = np.array([model.act(demos.images[k], float(demos.speed[k]), straight)[0] for k in idx])
    label = demos.steer[idx]
    return (f"local path, {len(idx)} validation steps: mean |change| of the steering with another step's path "
            f"{np.abs(other - own).mean():.3f}, with a straight path {np.abs(flat - own).mean():.3f}; MAE against the "
            f"labels {np.abs(own - label).mean():.3f} (own path), {np.abs(other - label).mean():.3f} (another's)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", choices=sorted(CONTROLLERS), default="lp")
    parser.add_argument("--config", default="config/config.yaml")
    parser.add_argument("--also", nargs="*", default=[], help="config files merged over --config (later ones win)")
    parser.add_argument("--controller", type=Path, help="checkpoint (default: the region's own)")
    parser.add_argument("--steps", type=int, default=600, help="steps drawn per half (hard, easy) and set")
    args = parser.parse_args()
    torch.set_num_threads(1)
    conf = load_layered(args.config, args.also)
    root = Path("results") / conf["region"]["name"] / "drive"
    demos = Demonstrations.load(root / "demonstrations.npz")
    val_routes = int(conf["drive"]["demonstrations"]["val_routes"])
    if val_routes < 2:
        raise SystemExit(f"drive.demonstrations.val_routes: {val_routes}; offline_steer.py needs at least 2")
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
    if args.agent == "lp":
        val_idx = np.flatnonzero(val)
        print("\n" + path_effect(model, demos, rng.choice(val_idx, min(args.steps, len(val_idx)), replace=False), rng))


if __name__ == "__main__":
    main()
