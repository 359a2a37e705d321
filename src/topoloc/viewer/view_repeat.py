"""Stage ``view_repeat``: the teach-and-repeat viewer (``results/{region}/viewer/teach_repeat.html``).

Inputs: ``graph`` (the roads), ``vertices`` (``build_topometric_map``: the map's vertices, their position and
command), ``frames`` (``localize_repeat``: per condition, method and repeat frame the vertex it localized to) and
``repeat`` (``render_places``' repeat ``places.npz``: the camera images). One repeat condition is shown
(``viewer.condition``, default the first): the topometric map and the repeat track as lines, each method's
localization (its vertex's position) over the slider's frames, the camera frame every ``viewer.image_every`` frames
(a downscaled JPEG) and the command of the localized vertex. With ``episodes`` (``follow_route``'s
``episodes.csv``, optional) also route following in closed loop: each evaluation route along the teach route, and
where each episode of the shown condition that failed stopped (its progress along the route). With ``traces``
(``follow_route``'s ``traces.csv.gz``, optional) each closed-loop drive of the shown condition can be picked and
replayed: the vehicle, its trail, speed and the command of its localized vertex, and where it stopped. The slider
moves the vehicle by progress: at a row that has driven ``d`` metres of the repeat drive the vehicle is at its last
trace point whose progress (the route's start plus its progress along the route) is at most ``d``. Output: ``html``.
"""

from __future__ import annotations

import base64
import logging
from typing import Any

import cv2
import numpy as np
import pandas as pd

from topoloc.drive.traces import read_traces
from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.viewer.page import ViewerData, agent, latlon_of, thin_rows, write_viewer

log = logging.getLogger(__name__)


def jpeg_uri(image: np.ndarray, quality: int = 70) -> str:
    """An RGB image as a base64 JPEG data URI."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("cannot encode a camera frame as JPEG")
    return "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def _table(path: str, columns: set[str], what: str) -> pd.DataFrame:
    try:
        table = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as err:
        raise InputError(path, f"cannot read the {what} ({err})") from err
    missing = columns - set(table.columns)
    if missing:
        raise InputError(path, f"not the {what} (no {sorted(missing)[0]!r} column)")
    return table


def read_episodes(path: str) -> pd.DataFrame:
    """``follow_route``'s ``episodes.csv``."""
    return _table(path, {"episode", "route", "route_start_m", "route_length_m", "condition", "agent", "outcome",
                         "success", "progress_m"}, "follow_route episodes table")


def add_episodes(data: ViewerData, episodes: pd.DataFrame, vertices: pd.DataFrame, condition: str, row_m: np.ndarray,
                 latlon: Any) -> None:
    """Route following: the routes as lines, a ``fail`` mark where each failed episode of ``condition`` stopped."""
    s, xy = vertices.s.to_numpy(float), vertices[["gt_x", "gt_y"]].to_numpy(float)
    for route, group in episodes.groupby("route"):
        start, length = float(group.route_start_m.iat[0]), float(group.route_length_m.iat[0])
        on = (s >= start) & (s <= start + length)
        if on.sum() >= 2:
            data.lines.append({"name": f"route following: route {route} ({length:.0f} m)", "color": "#2ca02c",
                               "latlngs": latlon(xy[on])})
    shown = episodes[episodes.condition.astype(str) == condition]
    for e in shown[~shown.success.astype(str).str.lower().eq("true")].itertuples():
        at = float(e.route_start_m) + float(e.progress_m)
        where = xy[int(np.argmin(np.abs(s - at)))]
        data.marks.append({"kind": "fail", "name": str(e.agent), "idx": int(np.argmin(np.abs(row_m - at))),
                           "lat": latlon(where)[0][0], "lon": latlon(where)[0][1],
                           "label": f"{e.agent}: {e.outcome} after {float(e.progress_m):.0f} m of route {e.route}"})
    ok = int(shown.success.astype(str).str.lower().eq("true").sum())
    data.notes.append(f"Route following ({condition}): {ok} of {len(shown)} episodes reached the end; red rings: "
                      "where the others stopped.")


def add_drives(data: ViewerData, path: str, episodes: pd.DataFrame | None, condition: str, row_m: np.ndarray,
               latlon: Any) -> None:
    """Closed-loop drives of ``condition`` from the traces at ``path``, to replay along the slider (``row_m``: the
    metres driven at each row of the repeat drive); outcome and route start from ``episodes`` (:func:`read_episodes`)."""
    traces = read_traces(path)
    traces = traces[traces.condition.astype(str) == condition]
    episodes = episodes.set_index("episode") if episodes is not None else pd.DataFrame()
    for key, run_ in traces.groupby("episode", sort=False):
        run_ = run_.sort_values("step")
        known = key in episodes.index
        start = float(episodes.route_start_m.at[key]) if known else 0.0
        along = start + np.maximum.accumulate(run_.s_m.to_numpy(float))
        idx = np.minimum(np.searchsorted(row_m, along), len(row_m) - 1)  # first row that has driven as far (or the last)
        pos = latlon(run_[["x", "y"]].to_numpy(float))
        outcome = str(episodes.outcome.at[key]) if known else "?"
        end = f"{outcome} after {float(episodes.progress_m.at[key]):.0f} m" if known else "end"
        text = [f"{t:.1f} s · {v:.1f} m/s · command {c} (vertex {x}) · steer {st:+.2f}"
                for t, v, c, x, st in zip(run_.t_s, run_.speed_mps, run_.command, run_.vertex, run_.steer)]
        first = run_.iloc[0]
        data.drives.append({"key": str(key), "outcome": outcome, "idx": idx.tolist(), "pos": pos, "text": text,
                            "end": pos[-1], "label": f"{first['agent']}, route {first['route']}, repeat {first['repeat']}: {end}"})
    if data.drives:
        data.notes.append("Closed loop: pick a drive; the black vehicle moves with the slider by its progress along the "
                          "route (trace, command of its localized vertex); a red cross marks where it stopped.")


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Write the teach-and-repeat viewer; its size, frames and methods."""
    view = conf["viewer"]
    graph = RoadGraph.load(inputs["graph"])
    latlon = latlon_of(graph.crs)
    vertices = _table(inputs["vertices"], {"vertex", "x", "y", "gt_x", "gt_y", "command"}, "topometric map's vertices")
    frames = _table(inputs["frames"], {"condition", "method", "frame", "gt_x", "gt_y", "vertex", "error_m"},
                    "localize_repeat frames table")
    conditions = list(dict.fromkeys(frames.condition.astype(str)))
    condition = view["condition"] or conditions[0]
    if condition not in conditions:
        raise InputError("viewer.condition", f"{condition!r} is not a repeat condition of {inputs['frames']} ({', '.join(conditions)})")
    shown = frames[frames.condition.astype(str) == condition]
    methods = list(dict.fromkeys(shown.method.astype(str)))
    track = shown[shown.method == methods[0]].sort_values("frame")
    count = len(track)
    rows = thin_rows(count, int(view["max_rows"]))
    truth_xy = track[["gt_x", "gt_y"]].to_numpy(float)
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(truth_xy, axis=0).T))])
    data = ViewerData(title=f"topoloc viewer: {conf['region']} teach and repeat ({condition})", sure=0.5,
                      time={"frame": track.frame.to_numpy()[rows].tolist(), "driven_m": np.round(driven[rows], 1).tolist(),
                            "t_s": None},
                      truth=latlon(truth_xy[rows]))
    data.lines.append({"name": "topometric map (teach vertices)", "color": "#ff7f0e",
                       "latlngs": latlon(vertices[["gt_x", "gt_y"]].to_numpy(float))})
    vxy = vertices.set_index("vertex")[["gt_x", "gt_y"]]
    command = vertices.set_index("vertex").command.astype(str)
    for i, method in enumerate(methods):
        run_ = shown[shown.method == method].sort_values("frame")
        row_of = np.searchsorted(rows, np.arange(len(run_)))
        keep = (row_of < len(rows)) & (rows[np.minimum(row_of, len(rows) - 1)] == np.arange(len(run_)))
        run_ = run_[keep]
        vertex = run_.vertex.to_numpy(np.int64)
        known = vertex >= 0
        pos = latlon(vxy.reindex(np.where(known, vertex, vertices.vertex.iat[0])).to_numpy(float))
        error = run_.error_m.to_numpy(float)
        data.agents.append(agent(method, method, i, row_of[keep], [p if k else None for p, k in zip(pos, known)],
                                 vertex, np.where(known, 1.0 / (1.0 + np.nan_to_num(error, nan=1e9)), 0.0), "vertex"))
        if i == 0:
            data.text = {"idx": row_of[keep].tolist(),
                         "text": [f"{method}: vertex {v}, command {command.get(v, '?')}, error {e:.1f} m" if v >= 0
                                  else f"{method}: not localized" for v, e in zip(vertex, error)]}
    episodes = read_episodes(inputs["episodes"]) if inputs.get("episodes") else None
    if episodes is not None:
        add_episodes(data, episodes, vertices, condition, driven[rows], latlon)
    if inputs.get("traces"):
        add_drives(data, inputs["traces"], episodes, condition,
                   np.asarray(data.time["driven_m"], float), latlon)  # the metres the slider shows
    npz = np.load(inputs["repeat"])
    images = npz["images"]
    names = [str(c) for c in npz["conditions"]] if "conditions" in npz.files else conditions
    if condition in names and images.ndim == 5:
        which = names.index(condition)
        every = int(view["image_every"])
        picks = [f for f in range(0, min(count, images.shape[1]), every)]
        data.images = {"idx": np.searchsorted(rows, picks).clip(0, len(rows) - 1).tolist(),
                       "src": [jpeg_uri(images[which, f]) for f in picks]}
    else:
        data.notes.append(f"no camera images of condition {condition} in {inputs['repeat']}")
    data.notes.append("Chart: 1 / (1 + localization error in metres) per method, over metres driven on the repeat drive.")
    size = write_viewer(outputs["html"], graph, data, view["tiles"])
    log.info("%s: %s, %d methods, %d frames, %.2f MB", outputs["html"], condition, len(methods), count, size / 2**20)
    return {"size_mb": size / 2**20, "methods": float(len(methods)), "frames": float(count)}
