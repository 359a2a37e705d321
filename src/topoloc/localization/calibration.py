"""Calibration of a localizer's confidence: does an answer given with confidence ``c`` turn out right a share ``c``
of the time?

The answers are binned by confidence into :data:`BINS` equal bins of ``[0, 1]`` (the last bin holds 1.0; with
10 bins it is ``[0.9, 1.0]``, the answers the evaluation calls *sure*). Per bin: the number of answers, their mean
confidence and the share of them that is right (the judge of :class:`topoloc.localization.evaluation.Judge`):
the *reliability diagram*. The *expected calibration error* is the mean over answers of the gap in their bin,

    ECE = sum_b (n_b / N) |share right_b - mean confidence_b|,

0 for a perfectly calibrated localizer, large for an over- or under-confident one (Guo et al., "On
calibration of modern neural networks", ICML 2017).

A localizer's confidence can be recalibrated (:class:`LogitCalibration`, fitted by :func:`fit_logit_calibration`):
a monotone map on the log-odds, which changes no answer, only how sure it is said to be.

The bin sums are additive: :func:`bin_sums` of one start's answers are columns of that start's row
(``cal_n_<b>``, ``cal_conf_<b>``, ``cal_right_<b>``), and :func:`reliability` / :func:`ece` of the rows of many
starts (summed) equal those of all their answers pooled.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

#: Confidence bins of [0, 1].
BINS = 10
#: The per-start columns of the bin sums: answers, summed confidence, right answers, per bin.
COLUMNS = [f"cal_{kind}_{b}" for kind in ("n", "conf", "right") for b in range(BINS)]


def bin_index(confidence: ArrayLike, bins: int = BINS) -> NDArray[np.int64]:
    """The bin of each confidence (clipped to [0, 1]; 1.0 falls in the last bin)."""
    c = np.clip(np.asarray(confidence, float), 0.0, 1.0)
    return np.minimum((c * bins).astype(np.int64), bins - 1)


def bin_sums(confidence: ArrayLike, right: ArrayLike, bins: int = BINS) -> dict[str, float]:
    """Per bin: the number of answers, the sum of their confidences and the number right (the :data:`COLUMNS`)."""
    c = np.nan_to_num(np.asarray(confidence, float), nan=0.0)
    r = np.asarray(right, bool)
    if c.shape != r.shape:
        raise ValueError(f"{c.shape} confidences for {r.shape} judgements")
    idx = bin_index(c, bins)
    n = np.bincount(idx, minlength=bins)
    conf = np.bincount(idx, weights=c, minlength=bins)
    hit = np.bincount(idx, weights=r.astype(float), minlength=bins)
    return {f"cal_{kind}_{b}": float(v[b]) for kind, v in (("n", n), ("conf", conf), ("right", hit)) for b in range(bins)}


def _totals(rows: pd.DataFrame | dict[str, float], bins: int) -> tuple[NDArray, NDArray, NDArray]:
    """(answers, summed confidence, right) per bin, summed over ``rows`` (one start each, or one dict)."""
    def column(kind: str) -> NDArray[np.float64]:
        return np.array([np.nansum(np.asarray(rows[f"cal_{kind}_{b}"], float)) for b in range(bins)])
    return column("n"), column("conf"), column("right")


def reliability(rows: pd.DataFrame | dict[str, float], bins: int = BINS) -> pd.DataFrame:
    """The reliability diagram of the answers of ``rows`` (bin sums of one or many starts): per bin its bounds, the
    number of answers, their mean confidence and the share right (NaN in an empty bin)."""
    n, conf, right = _totals(rows, bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        return pd.DataFrame({"low": np.arange(bins) / bins, "high": np.arange(1, bins + 1) / bins, "answers": n.astype(np.int64),
                             "confidence": np.where(n > 0, conf / n, np.nan), "share_right": np.where(n > 0, right / n, np.nan)})


def reliability_per(rows: pd.DataFrame, by: str = "localizer", skip: Sequence[str] = ()) -> dict[str, pd.DataFrame]:
    """The reliability diagram of each group of ``rows`` (bin sums of starts) by the column ``by``, in the order the
    groups first appear, but those named in ``skip`` (the oracle, which gives no answers)."""
    return {str(name): reliability(group) for name, group in rows.groupby(by, sort=False) if name not in skip}


def ece(rows: pd.DataFrame | dict[str, float], bins: int = BINS) -> float:
    """The expected calibration error of the answers of ``rows`` (NaN without answers)."""
    n, conf, right = _totals(rows, bins)
    total = n.sum()
    if total <= 0:
        return float("nan")
    return float(np.abs(right - conf).sum() / total)  # sum_b n_b / N |right_b / n_b - conf_b / n_b|


def expected_calibration_error(confidence: ArrayLike, right: ArrayLike, bins: int = BINS) -> float:
    """ECE of answers given directly (confidence per answer and whether it is right)."""
    return ece(bin_sums(confidence, right, bins), bins)


class LogitCalibration:
    """A localizer's confidence recalibrated on the log-odds, ``logit(c') = scale logit(c) + shift`` (Platt scaling;
    ``shift`` 0 is Guo et al.'s temperature ``1 / scale``). Monotone for ``scale`` > 0, so the ranking of places and
    every answer stay as they were; ``scale`` 1 and ``shift`` 0 leave the confidence as it is."""

    def __init__(self, scale: float = 1.0, shift: float = 0.0) -> None:
        if not scale > 0:
            raise ValueError(f"confidence scale must be > 0, got {scale}")
        self.scale, self.shift = float(scale), float(shift)
        self.identity = self.scale == 1.0 and self.shift == 0.0
        self._odds = math.exp(self.shift)

    def __call__(self, confidence: float) -> float:
        """One confidence, recalibrated (0 and 1 stay 0 and 1)."""
        if self.identity or not 0.0 < confidence < 1.0:
            return confidence
        num = self._odds * confidence ** self.scale  # e^shift c^scale / (e^shift c^scale + (1 - c)^scale)
        return num / (num + (1.0 - confidence) ** self.scale)

    def array(self, confidence: ArrayLike) -> NDArray[np.float64]:
        """Many confidences, recalibrated."""
        c = np.asarray(confidence, float)
        if self.identity:
            return c.copy()
        with np.errstate(divide="ignore"):
            num = self._odds * np.power(c, self.scale)
            out = num / (num + np.power(1.0 - c, self.scale))
        return np.where((c > 0) & (c < 1), out, np.clip(c, 0.0, 1.0))


def fit_logit_calibration(confidence: ArrayLike, right: ArrayLike, iterations: int = 50) -> LogitCalibration:
    """The :class:`LogitCalibration` of largest likelihood of the judgements ``right`` given the ``confidence`` of each
    answer (logistic regression on the log-odds, Newton's method); confidences are clipped to [1e-6, 1 - 1e-6]."""
    c = np.clip(np.asarray(confidence, float), 1e-6, 1.0 - 1e-6)
    y = np.asarray(right, float)
    if c.shape != y.shape or not len(c):
        raise ValueError(f"{c.shape} confidences for {y.shape} judgements")
    x = np.stack([np.log(c / (1.0 - c)), np.ones_like(c)], axis=1)
    w = np.array([1.0, 0.0])
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-(x @ w)))
        hessian = (x * (p * (1.0 - p))[:, None]).T @ x + 1e-9 * np.eye(2)
        step = np.linalg.solve(hessian, x.T @ (y - p))
        w += step
        if np.abs(step).max() < 1e-10:
            break
    return LogitCalibration(float(w[0]), float(w[1]))
