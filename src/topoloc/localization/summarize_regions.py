"""Stage ``summarize_regions``: localization of every region and drive of a multi-region run, side by side.

Inputs: ``csv_<region>`` for each region of ``conf['regions']``, the ``csv`` of that region's
``evaluate_localization`` (one row per drive and localizer, and ``all`` over its drives). Outputs: ``csv`` (the
rows of every region with a ``region`` column first), ``table`` (markdown: localized share, median distance to
localized, accuracy after and the oracle's resolved share, then where the summary has them the median ratio to the
oracle, the position error, the confident-wrong share and the expected calibration error, per region, drive and
localizer, the oracle first) and ``figure`` (the localized share per region and drive, one bar per localizer).
Metrics: ``<region>/<drive>/<localizer>/<figure>`` for the localized share, the confident-wrong share and the ECE.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from topoloc.errors import InputError
from topoloc.io import atomic_path, write_text

#: The columns of the cross-region table (from evaluate_localization's summary).
COLUMNS = {"starts": "starts", "localized_share": "localized", "median_m": "median m",
           "accuracy_after": "acc. after", "oracle_resolved": "oracle resolved"}
#: Further columns, shown where the summary has them (summaries before they existed lack them).
EXTRA = {"median_ratio": "median ratio", "position_error_m": "position error m", "confident_wrong": "confident wrong",
         "ece": "ECE"}
#: The formats of the columns.
FORMATS = {"starts": "{:.0f}", "median_m": "{:.0f}", "median_ratio": "{:.2f}", "position_error_m": "{:.1f}",
           "confident_wrong": "{:.2%}"}


def load(regions: list[str], inputs: dict[str, str]) -> pd.DataFrame:
    """The summary rows of every region, with a ``region`` column first."""
    frames = []
    for region in regions:
        path = inputs[f"csv_{region}"]
        frame = pd.read_csv(path)
        missing = {"drive", "localizer", *COLUMNS} - set(frame.columns)
        if missing:
            raise InputError(path, f"not a localization summary of evaluate_localization (no {min(missing)!r} column)")
        frames.append(frame.assign(region=region)[["region", *frame.columns]])
    return pd.concat(frames, ignore_index=True)


def markdown(summary: pd.DataFrame) -> str:
    """The table: one row per region, drive and localizer."""
    head = ["region", "drive", "localizer", *COLUMNS.values(), *EXTRA.values()]
    lines = ["# Localization per region and drive", "",
             ("Localized = share of the starts localized (see each region's localization.md); median m = median "
              "distance to localized; acc. after = accuracy after localizing; oracle resolved = share of the starts "
              "the map's uniqueness limit resolves; median ratio = localized / oracle distance on those; position "
              "error = median distance of the answer's position to the truth after localizing; confident wrong = "
              "share of all answers wrong with confidence >= localization.evaluate.sure; ECE = expected calibration "
              "error of all answers."), "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in summary.itertuples(index=False):
        values = [row.region, row.drive, row.localizer]
        for key in [*COLUMNS, *EXTRA]:
            value = getattr(row, key, float("nan"))
            values.append("" if pd.isna(value) or (key in EXTRA and row.localizer == "oracle")
                          else FORMATS.get(key, "{:.3f}").format(value))
        lines.append("| " + " | ".join(map(str, values)) + " |")
    return "\n".join(lines) + "\n"


def figure(summary: pd.DataFrame, path: str | Path) -> None:
    """Localized share per region and drive (groups), one bar per localizer."""
    groups = list(dict.fromkeys(zip(summary.region, summary.drive, strict=True)))
    localizers = list(dict.fromkeys(summary.localizer))
    width = 0.8 / max(1, len(localizers))
    fig, ax = plt.subplots(figsize=(max(6.0, 1.4 * len(groups) * max(1, len(localizers)) * width + 2), 4))
    for k, name in enumerate(localizers):
        rows = summary[summary.localizer == name].set_index(["region", "drive"])
        values = [float(rows.localized_share.get(g, np.nan)) for g in groups]
        ax.bar(np.arange(len(groups)) + (k - (len(localizers) - 1) / 2) * width, values, width, label=name)
    ax.set_xticks(np.arange(len(groups)), [f"{region}\n{drive}" for region, drive in groups])
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("share of starts localized")
    ax.set_title("Localization per region and drive")
    ax.legend(fontsize=7, ncol=min(4, len(localizers)), loc="upper right")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


def run(conf: dict[str, Any], inputs: dict[str, str], outputs: dict[str, str]) -> dict[str, float]:
    """Write ``csv``, ``table`` and ``figure`` of the regions of ``conf['regions']``."""
    summary = load(list(conf["regions"]), inputs)
    with atomic_path(outputs["csv"]) as tmp:
        summary.to_csv(tmp, index=False, float_format="%.4f")
    write_text(outputs["table"], markdown(summary))
    figure(summary, outputs["figure"])
    return {f"{r.region}/{r.drive}/{r.localizer}/{key}": float(getattr(r, key))
            for r in summary.itertuples(index=False) for key in ("localized_share", "confident_wrong", "ece")
            if pd.notna(getattr(r, key, float("nan")))}
