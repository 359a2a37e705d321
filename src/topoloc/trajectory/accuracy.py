"""Accuracy of the trajectory RNN's predictions: at the i-th position (the paper's Eq. 6), against metres driven, and
the ceiling of any causal model (:func:`prefix_majority`)."""

from __future__ import annotations

import numpy as np
import pandas as pd


def accuracy_by_position(predictions: list[np.ndarray], labels: list[np.ndarray]) -> pd.DataFrame:
    """Rows ``position`` (1-based, then ``last``), ``n`` trajectories with that position, ``accuracy``."""
    if not labels:
        return pd.DataFrame(columns=["position", "n", "accuracy"])
    longest = max(len(lab) for lab in labels)
    correct = np.zeros(longest)
    count = np.zeros(longest)
    for pred, lab in zip(predictions, labels):
        hits = pred == lab
        correct[: len(lab)] += hits
        count[: len(lab)] += 1
    last = float(np.mean([p[-1] == lab[-1] for p, lab in zip(predictions, labels)]))
    rows = [{"position": str(i + 1), "n": int(count[i]), "accuracy": correct[i] / count[i]} for i in range(longest)]
    rows.append({"position": "last", "n": len(labels), "accuracy": last})
    return pd.DataFrame(rows)


def accuracy_by_distance(predictions: list[np.ndarray], labels: list[np.ndarray], metres: list[np.ndarray],
                         bin_m: float = 100.0) -> pd.DataFrame:
    """Rows ``metres`` (upper edge of each ``bin_m`` bin of distance driven), ``n`` tokens in it, ``accuracy``.

    ``metres``: per trajectory, the distance driven up to each token (from the ``distance`` feature).
    """
    pred = np.concatenate([np.asarray(p) == np.asarray(y) for p, y in zip(predictions, labels)]) if labels else np.zeros(0)
    where = np.concatenate(metres) if metres else np.zeros(0)
    bins = np.floor(where / bin_m).astype(int)
    rows = [{"metres": float((b + 1) * bin_m), "n": int(np.sum(bins == b)), "accuracy": float(pred[bins == b].mean())}
            for b in np.unique(bins)]
    return pd.DataFrame(rows, columns=["metres", "n", "accuracy"])


def driven_metres(inputs: list[np.ndarray], spacing_m: float) -> list[np.ndarray]:
    """Distance driven up to each token, from the first feature column (metres since the last token / spacing)."""
    return [np.cumsum(f[:, 0].astype(float)) * spacing_m for f in inputs]


def prefix_majority(reference_tokens: list[np.ndarray], reference_labels: list[np.ndarray],
                    tokens: list[np.ndarray]) -> list[np.ndarray]:
    """Best causal guess at every step: the most frequent label among reference paths with the same token prefix.

    A causal model sees only the tokens so far; paths of the map that share a
    prefix but sit on different edges at its end are indistinguishable to it.
    Scored with :func:`accuracy_by_position`, these guesses give the ceiling
    any causal model can reach on ``tokens`` when ``reference`` holds every path.
    Prefixes absent from the reference get the label -1.
    """
    counts: dict[int, dict[int, int]] = {}
    for seq, lab in zip(reference_tokens, reference_labels):
        key = 0
        for token, label in zip(seq.tolist(), lab.tolist()):
            key = hash((key, token))
            slot = counts.setdefault(key, {})
            slot[label] = slot.get(label, 0) + 1
    best = {key: max(slot, key=lambda label: (slot[label], -label)) for key, slot in counts.items()}
    guesses = []
    for seq in tokens:
        key, row = 0, []
        for token in seq.tolist():
            key = hash((key, token))
            row.append(best.get(key, -1))
        guesses.append(np.array(row, dtype=np.int64))
    return guesses
