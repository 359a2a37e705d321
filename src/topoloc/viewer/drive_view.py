"""The viewer of a drive on a road graph: every localizer's answers over time, the truth where known, the metric
filter's belief, the starts and where each localizer and the oracle became sure (used by the ``view_drive``
stage and by ``topoloc localize --html``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from topoloc.errors import InputError
from topoloc.graph.road_graph import RoadGraph
from topoloc.localization.roadmap import RoadMap
from topoloc.localizer import ROAD_OBSERVATIONS
from topoloc.motion.poses import Odometry
from topoloc.registry import registry
from topoloc.viewer.belief import belief_moments
from topoloc.viewer.page import ViewerData, agent, latlon_of, mark, rows_of, thin_rows

#: Columns the viewer reads from an answers table (others, e.g. added top-k columns, are ignored).
ANSWER_COLUMNS = ["localizer", "frame", "state", "confidence", "x", "y"]


def check_answers(table: pd.DataFrame, where: str) -> pd.DataFrame:
    """The answers table with the columns the viewer reads; InputError naming ``where`` if one is missing."""
    missing = [c for c in ANSWER_COLUMNS if c not in table.columns]
    if missing:
        raise InputError(where, f"not an answers table (no {missing[0]!r} column)")
    return table


def sure_frame(driven: NDArray[np.float64], start: int, localized_m: float) -> int | None:
    """The frame at which a run from ``start`` has driven ``localized_m`` metres (None: never, NaN)."""
    if not np.isfinite(localized_m):
        return None
    return int(min(np.searchsorted(driven, driven[start] + localized_m), len(driven) - 1))


def drive_data(title: str, graph: RoadGraph, odometry: Odometry, answers: pd.DataFrame | None, conf: dict[str, Any],
               truth_xy: NDArray[np.float64] | None = None, times: NDArray[np.float64] | None = None,
               starts: list[int] | None = None, localized_m: dict[str, float] | None = None,
               road: RoadMap | None = None) -> ViewerData:
    """The viewer's data of one drive.

    ``answers``: one run per localizer from the drive's first frame (columns :data:`ANSWER_COLUMNS`), or None for
    the metric filter's answers of the belief's run (city maps: one localizer, run once). ``truth_xy``:
    the true (or georeferenced) position per frame, in the graph's CRS, or None. ``starts``: the evaluation's start
    frames. ``localized_m``: per localizer (and ``oracle``) the metres from the first start until it was localized,
    as the evaluation counts it; None: where the answer first reaches ``localization.evaluate.sure``. ``road``: the
    caller's road map of ``graph``, whose cached map structures the belief's run reuses (default: a new one)."""
    view = conf["viewer"]
    latlon = latlon_of(graph.crs)
    count = len(odometry)
    driven = truth_driven(truth_xy) if truth_xy is not None else odometry.driven_m
    row_frames = thin_rows(count, int(view["max_rows"]))
    data = ViewerData(title=title, sure=float(conf["localization"]["evaluate"]["sure"]),
                      time={"frame": row_frames.tolist(), "driven_m": np.round(driven[row_frames], 1).tolist(),
                            "t_s": np.round(np.asarray(times, float)[row_frames], 2).tolist() if times is not None else None})
    if truth_xy is not None:
        data.truth = latlon(truth_xy[row_frames])
    if road is None:
        road = RoadMap(graph, conf["localization"]["decode"]["u_turns"], conf["localization"]["decode"]["max_skip_m"])
    loc_conf = {k: conf[k] for k in ("localization", "segmentation", "encoding")}
    belief = belief_moments(road, odometry, loc_conf, float(view["belief_every_m"]), int(view["top_roads"]),
                            int(view["heat_points"]), latlon)
    if belief["frame"]:
        data.belief = {"idx": rows_of(belief["frame"], row_frames).tolist(), "roads": belief["roads"], "heat": belief["heat"],
                       "names": road_names(graph, belief["roads"])}
    if answers is None:
        answers = belief["answers"]
    labels = {name: cls.label for name, cls in registry(ROAD_OBSERVATIONS).items()}
    sure = float(conf["localization"]["evaluate"]["sure"])
    first_start = int(starts[0]) if starts else 0
    for i, (name, run) in enumerate(answers.groupby("localizer", sort=False)):
        run = run.sort_values("frame")
        frames = run.frame.to_numpy(np.int64)
        xy = run[["x", "y"]].to_numpy(float)
        has = np.isfinite(xy).all(axis=1)
        pos = None
        if has.any():
            ll = latlon(np.where(has[:, None], xy, 0.0))
            pos = [p if h else None for p, h in zip(ll, has)]
        conf_ = run.confidence.to_numpy(float)
        data.agents.append(agent(str(name), labels.get(str(name), str(name)), i, rows_of(frames, row_frames), pos,
                                 run.state.to_numpy(np.int64), conf_))
        if localized_m is not None:
            frame = sure_frame(driven, first_start, localized_m.get(str(name), np.nan))
        else:
            reached = np.flatnonzero(conf_ >= sure)
            frame = int(frames[reached[0]]) if len(reached) else None
        if frame is not None:
            where = truth_xy[frame] if truth_xy is not None else (xy[has][0] if has.any() else None)
            if where is not None:
                data.marks.append(mark("sure", str(name), int(rows_of([frame], row_frames)[0]), latlon(where)[0],
                                       f"{name} sure after {driven[frame] - driven[first_start]:.0f} m"))
    if localized_m is not None and truth_xy is not None:
        frame = sure_frame(driven, first_start, localized_m.get("oracle", np.nan))
        if frame is not None:
            data.marks.append(mark("oracle", "oracle", int(rows_of([frame], row_frames)[0]), latlon(truth_xy[frame])[0],
                                   f"oracle: unique after {driven[frame] - driven[first_start]:.0f} m"))
    for k, start in enumerate(starts or []):
        if truth_xy is not None:
            data.marks.append(mark("start", "starts", int(rows_of([start], row_frames)[0]), latlon(truth_xy[start])[0],
                                   f"start {k} at {driven[start]:.0f} m (frame {start})"))
    return data


def truth_driven(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Metres driven along a track, per point."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(np.asarray(xy, float), axis=0).T))])


def road_names(graph: RoadGraph, moments: list[list[list[float]]]) -> dict[str, str]:
    """The name of every road that leads at some moment (for the belief's list), by edge id."""
    edges = {int(e) for roads in moments for e, _ in roads}
    names = {}
    for e in sorted(edges):
        name = graph.edges["name"].iat[e]
        names[str(e)] = name if isinstance(name, str) and name else f"{graph.edges['highway'].iat[e]} road"
    return names
