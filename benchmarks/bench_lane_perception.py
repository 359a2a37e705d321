"""How well the controllers' image encoder learns where the vehicle stands against its lane, from the demonstrations.

Usage (after ``snakemake all`` built ``results/<region>/drive/demonstrations.npz``)::

    python -m benchmarks.bench_lane_perception [--configfile config/config.yaml] [--steps 400,1600]

The controllers' image encoder (``drive.network``: downsample, local-contrast normalisation, the convolution stages
and the layer of ``hidden`` units, with the training's photometric augmentation) and a head of two numbers trained
from scratch on the demonstrations' images alone, supervised directly with the vehicle's offset from the lane (m, +
lane to the left) and the lane's heading 1-2 m ahead in the vehicle frame (what Topo-LP must read from its image to
follow a path: docs/route_following.md, "The map's path is enough"). Batches of ``drive.train.batch_size`` from the
training routes, Adam at ``drive.train.lr``; after each budget of ``--steps``: the correlation and the RMS error on
the validation routes (the last ``--val-share`` of them) and on as many training steps, beside the labels' spread (a head that always answers the mean
has an RMS error of the spread and no correlation). ``--against road`` scores the offset of the nearest map road's
centre line instead of the lane's: the expert keeps a quarter of the carriageway right of a dashed centre line and
the middle of any other road, so the lane's offset also asks whether that thin line is there.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import shapely
import torch
from torch import nn
from torch.nn import functional as F
from tqdm import tqdm

from benchmarks.markdown import add_out_option, markdown_copy
from topoloc.config import load
from topoloc.drive.controller_training import build_model
from topoloc.drive.demonstrations import Demonstrations
from topoloc.graph.road_graph import RoadGraph
from topoloc.place.network import augment


def lane_pose(path: np.ndarray) -> np.ndarray:
    """``(n, 2)``: the lane's offset at the vehicle (m, + left; the recorded path 1 and 2 m ahead extended back to the
    vehicle) and its heading between 1 and 2 m ahead (rad, + left) of recorded local paths ``(n, P, 2)``."""
    at_vehicle = 2.0 * path[:, 0] - path[:, 1]
    tangent = path[:, 1] - path[:, 0]
    return np.column_stack([at_vehicle[:, 1], np.arctan2(tangent[:, 1], tangent[:, 0])]).astype(np.float32)


def road_middle_offset(graph: RoadGraph, xy: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """``(n,)``: the offset (m, + left) of the nearest map road's centre line from each pose ``xy`` (map metres) with
    heading ``yaw`` (rad): what the road's edges show, whatever lane the expert keeps on it."""
    lines = [shapely.LineString(c) for c in graph.geometry]
    points = shapely.points(xy)
    nearest = shapely.STRtree(lines).nearest(points)
    foot = np.array([np.asarray(lines[e].interpolate(lines[e].project(p)).coords[0]) for e, p in zip(nearest, points)])
    d = foot - xy
    return (-np.sin(yaw) * d[:, 0] + np.cos(yaw) * d[:, 1]).astype(np.float32)


def scores(predicted: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Correlation and RMS error of each column (offset in m, heading in deg) and the truth's spread."""
    out = {}
    for k, (name, unit) in enumerate((("offset", 1.0), ("heading", float(np.degrees(1.0))))):
        out[f"{name}_corr"] = float(np.corrcoef(predicted[:, k], truth[:, k])[0, 1])
        out[f"{name}_rmse"] = float(np.sqrt(np.mean((predicted[:, k] - truth[:, k]) ** 2)) * unit)
        out[f"{name}_sd"] = float(truth[:, k].std() * unit)
    return out


class LanePerception(nn.Module):
    """The controllers' image encoder with a head of (offset, heading)."""

    def __init__(self, drive: dict, demos: Demonstrations) -> None:
        super().__init__()
        self.controller = build_model(drive, demos, "dlm")
        self.head = nn.Sequential(nn.Linear(int(drive["network"]["hidden"]), 64), nn.ReLU(inplace=True), nn.Linear(64, 2))

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        c = self.controller
        return self.head(c.image_fc(torch.flatten(c.encoder(c._normalize(images)), 1)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configfile", default="config/config.yaml")
    parser.add_argument("--demonstrations", help="default: results/<region>/drive/demonstrations.npz")
    parser.add_argument("--steps", default="400,1600", help="training budgets (batches) to score after, ascending")
    parser.add_argument("--against", choices=("lane", "road"), default="lane",
                        help="the offset of the expert's lane, or of the nearest map road's centre line")
    parser.add_argument("--val-share", type=float, help="validate on this share of the routes, the last ones (default: "
                        "drive.demonstrations.val_routes of them; one route is a noisy score)")
    add_out_option(parser, "bench_lane_perception")
    args = parser.parse_args()
    torch.set_num_threads(2)
    with markdown_copy(args.out):
        config = load(Path(args.configfile))
        drive = config["drive"]
        path = Path(args.demonstrations or Path("results") / config["region"]["name"] / "drive" / "demonstrations.npz")
        demos = Demonstrations.load(path)
        labels = lane_pose(demos.path)
        if args.against == "road":
            graph = RoadGraph.load(Path("results") / config["region"]["name"] / "graph" / "graph.graphml")
            labels[:, 0] = road_middle_offset(graph, demos.xy, demos.yaw)
        routes = int(demos.route.max()) + 1
        held = int(drive["demonstrations"]["val_routes"]) if args.val_share is None else round(args.val_share * routes)
        if not 1 <= held < routes:
            raise SystemExit(f"--val-share: {held} of {routes} routes held out; hold out at least one and not all")
        val = np.flatnonzero(demos.route >= routes - held)
        train = np.setdiff1d(np.arange(len(demos)), val)
        rng = np.random.default_rng(int(drive["train"]["seed"]))
        seen_train = rng.choice(train, min(len(val), len(train)), replace=False)
        torch.manual_seed(int(drive["train"]["seed"]))
        model = LanePerception(drive, demos)
        opt = torch.optim.Adam(model.parameters(), lr=float(drive["train"]["lr"]),
                               weight_decay=float(drive["train"]["weight_decay"]))
        generator = torch.Generator().manual_seed(int(drive["train"]["seed"]))
        batch, done = int(drive["train"]["batch_size"]), 0
        scale = torch.tensor([1.0, 10.0])  # heading in units of 0.1 rad: both targets about 1 in spread

        def images(idx: np.ndarray) -> torch.Tensor:
            return model.controller._shrink(torch.from_numpy(demos.images[idx]).permute(0, 3, 1, 2).float())

        print(f"# Lane perception of the controllers' encoder, offset of the {args.against} ({path}: {routes - held} "
              f"training routes, {len(train)} steps; {held} validation routes, {len(val)} steps; {tuple(demos.images.shape[1:])} images, downsample "
              f"{drive['network']['downsample']})\n")
        print("| steps | set | offset corr | offset RMS (m) | offset spread (m) | heading corr | heading RMS (deg) | "
              "heading spread (deg) |\n|---|---|---|---|---|---|---|---|")
        for budget in sorted(int(s) for s in args.steps.split(",")):
            model.train()
            for _ in tqdm(range(budget - done), desc=f"training to {budget} steps", unit="batch", mininterval=5.0):
                idx = rng.choice(train, batch)
                x = images(idx)
                if drive["train"]["augment"]:
                    x = augment(x, generator, shift_px=0)
                loss = F.mse_loss(model(x), torch.from_numpy(labels[idx]) * scale)
                opt.zero_grad()
                loss.backward()
                opt.step()
            done = budget
            model.eval()
            for name, idx in (("validation", val), ("training", seen_train)):
                with torch.no_grad():
                    predicted = torch.cat([model(images(idx[i:i + 256])) for i in range(0, len(idx), 256)]) / scale
                s = scores(predicted.numpy(), labels[idx])
                print(f"| {budget} | {name} | {s['offset_corr']:.2f} | {s['offset_rmse']:.2f} | {s['offset_sd']:.2f} | "
                      f"{s['heading_corr']:.2f} | {s['heading_rmse']:.1f} | {s['heading_sd']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
