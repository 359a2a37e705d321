"""Localization metrics of a decoded drive against its ground-truth edges.

Per decoder:

* ``accuracy``: share of steps whose online answer (the best hypothesis after
  that step) is the true edge; ``path_accuracy`` the same for the decoded
  edge sequence (the best final hypothesis traced back).
* ``consistency``: share of consecutive decoded edges that are connected
  (same road, or one step apart on the map, see
  :func:`topoloc.localization.connectivity.consecutive_connected`).
* ``localized_m``: distance driven until localized, i.e. the start of the first
  stretch on which the online answer is right at every step for at least
  ``confirm_m`` metres (or to the end of the drive); NaN if never.
* ``accuracy_after``: share of the steps from there on with the right online answer.
* ``right_from_m``: the distance from which the online answer is right at every
  later step (strict; a single late miss pushes it to the end), NaN if the last step is wrong.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from topoloc.localization.connectivity import DirectedEdges, consecutive_connected


def localized_step(correct: NDArray[np.bool_], distance: NDArray[np.float64], confirm_m: float) -> int | None:
    """First step that starts a run of right answers lasting ``confirm_m`` metres or to the end; None if none."""
    correct = np.asarray(correct, bool)
    n = len(correct)
    # end of the run of right answers that contains each step (exclusive)
    run_end = np.empty(n, np.int64)
    end = n
    for t in range(n - 1, -1, -1):
        if not correct[t]:
            end = t
        run_end[t] = end
    for t in np.flatnonzero(correct):
        last = run_end[t] - 1
        if run_end[t] == n or distance[last] - distance[t] >= confirm_m:
            return int(t)
    return None


def drive_metrics(truth: NDArray[np.int64], online: NDArray[np.int64], path: NDArray[np.int64],
                  distance: NDArray[np.float64], states: DirectedEdges, confirm_m: float,
                  keys: NDArray[np.int64] | None = None) -> dict[str, float]:
    """The metrics of one decoder on one drive (see the module docstring)."""
    truth, online, path = (np.asarray(a, np.int64) for a in (truth, online, path))
    distance = np.asarray(distance, float)
    correct = online == truth
    step = localized_step(correct, distance, confirm_m)
    wrong = np.flatnonzero(~correct)
    right_from = np.nan if len(wrong) and wrong[-1] == len(truth) - 1 else float(distance[wrong[-1] + 1] if len(wrong) else distance[0])
    connected = consecutive_connected(states, path, keys)
    return {
        "steps": float(len(truth)),
        "length_m": float(distance[-1] - distance[0]) if len(distance) else 0.0,
        "accuracy": float(correct.mean()),
        "path_accuracy": float((path == truth).mean()),
        "consistency": float(connected.mean()) if len(connected) else 1.0,
        "localized_m": float(distance[step]) if step is not None else np.nan,
        "steps_after": float(len(truth) - step) if step is not None else 0.0,
        "accuracy_after": float(correct[step:].mean()) if step is not None else np.nan,
        "path_accuracy_after": float((path[step:] == truth[step:]).mean()) if step is not None else np.nan,
        "right_from_m": right_from,
    }
