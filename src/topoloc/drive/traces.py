"""The per-step trace of the closed-loop repeat drives (``follow_route``'s ``traces``, read by the teach-and-repeat
viewer): per drive a few rows a second (``drive.follow.trace_hz``) of where the vehicle was, its heading and speed,
the map vertex its localization gave, that vertex's command and position, and the steering commanded.

One gzipped CSV, one row per kept step, columns :data:`TRACE_COLUMNS`: ``episode`` (the key of ``episodes.csv``),
``route``, ``condition``, ``repeat``, ``agent`` (as in ``episodes.csv``, e.g. ``Topo-LP (place_loop)``),
``localization``, ``step`` (control step; the last row of a drive is where it ended, after its last step),
``t_s``, ``s_m`` (progress along the route's lane), ``x``, ``y`` (the vehicle's centre, in the graph's CRS),
``yaw`` (rad from east), ``speed_mps``, ``steer`` (the steering commanded at that step), ``vertex`` (localized),
``command`` (of that vertex) and ``loc_x``, ``loc_y`` (the localized vertex's true position).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from topoloc.drive.episodes import Episode
from topoloc.errors import InputError
from topoloc.io import atomic_path
from topoloc.place.topometric_map import COMMANDS, TopometricMap

TRACE_COLUMNS = ["episode", "route", "condition", "repeat", "agent", "localization", "step", "t_s", "s_m", "x", "y",
                 "yaw", "speed_mps", "steer", "vertex", "command", "loc_x", "loc_y"]


def trace_steps(steps: int, control_hz: float, trace_hz: float) -> np.ndarray:
    """The kept steps of a drive of ``steps`` control steps: every ``control_hz / trace_hz``-th from 0, and the last
    (``steps``: where the drive ended)."""
    every = max(1, int(round(control_hz / trace_hz)))
    return np.unique(np.append(np.arange(0, steps + 1, every), steps))


def episode_trace(episode: Episode, topo: TopometricMap, control_hz: float, trace_hz: float, /,
                  **labels: object) -> pd.DataFrame:
    """The trace rows of one drive (``labels``: the episode, route, condition, repeat, agent and localization)."""
    if len(episode.xy) != episode.steps + 1 or len(episode.vertex) != episode.steps:
        raise ValueError(f"episode {labels.get('episode')}: {len(episode.xy)} positions and {len(episode.vertex)} "
                         f"localizations for {episode.steps} steps")
    keep = trace_steps(episode.steps, control_hz, trace_hz)
    at = np.minimum(keep, max(episode.steps - 1, 0))  # the end row: the last step's localization and command
    vertex = episode.vertex[at] if episode.steps else np.zeros(len(keep), np.int64)
    steer = episode.steer[at] if episode.steps else np.zeros(len(keep))
    commands = np.asarray(COMMANDS)[topo.command[vertex].astype(int)]
    table = pd.DataFrame({**{k: labels.get(k) for k in TRACE_COLUMNS[:6]}, "step": keep,
                          "t_s": np.round(keep / control_hz, 2), "s_m": np.round(episode.s[keep], 2),
                          "x": np.round(episode.xy[keep, 0], 2), "y": np.round(episode.xy[keep, 1], 2),
                          "yaw": np.round(episode.yaw[keep], 3), "speed_mps": np.round(episode.speed[keep], 2),
                          "steer": np.round(steer, 3), "vertex": vertex, "command": commands,
                          "loc_x": np.round(topo.gt_xy[vertex, 0], 2), "loc_y": np.round(topo.gt_xy[vertex, 1], 2)})
    return table[TRACE_COLUMNS]


def write_traces(tables: list[pd.DataFrame], path: str | Path) -> int:
    """Write the drives' traces as one gzipped CSV, atomically; its size in bytes."""
    table = pd.concat(tables, ignore_index=True) if tables else pd.DataFrame(columns=TRACE_COLUMNS)
    with atomic_path(path) as tmp:
        table.to_csv(tmp, index=False, compression="gzip")
    return Path(path).stat().st_size


def read_traces(path: str | Path) -> pd.DataFrame:
    """The traces table at ``path``; InputError naming it if it cannot be read or lacks a column."""
    try:
        table = pd.read_csv(path, compression="infer")
    except (OSError, EOFError, pd.errors.ParserError, pd.errors.EmptyDataError) as err:
        raise InputError(str(path), f"cannot read the follow_route traces ({err})") from err
    missing = [c for c in TRACE_COLUMNS if c not in table.columns]
    if missing:
        raise InputError(str(path), f"not the follow_route traces (no {missing[0]!r} column)")
    return table
