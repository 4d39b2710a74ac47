"""Excursions in the report's time plots: stretches outside the tracked room, labelled.

An excursion (:mod:`loceval.metrics.excursions`) is a reference loss longer than the minimum while
an estimate went on; the time plots draw each as a hatched band over the grey tracking-loss
band, with the drift it measured written above it ("45 s, 38 m: 0.02 -> 0.21 m").
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

import numpy as np

from exporters.plots.figure import seconds_since
from loceval.evaluation import EvaluationResult

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["excursion_note", "mark_excursions"]

_EXCURSION_COLOUR: Final = "#6a1b9a"


def mark_excursions(ax: Axes, result: EvaluationResult, t0_ns: int) -> None:
    """Draw every estimate's excursions as hatched, labelled bands (one per stretch)."""
    seen: set[tuple[int, int]] = set()
    for estimate in result.estimates:
        for excursion in estimate.excursions:  # a few stretches per run
            key = (excursion.start_ns, excursion.end_ns)
            start, end = seconds_since(np.array(key, dtype=np.int64), t0_ns).tolist()
            if key not in seen:
                ax.axvspan(
                    start,
                    end,
                    facecolor="none",
                    edgecolor=_EXCURSION_COLOUR,
                    hatch="//",
                    linewidth=0.6,
                    label="excursion (outside the tracked room)" if not seen else None,
                )
                seen.add(key)
            before = "–" if excursion.error_before_m is None else f"{excursion.error_before_m:.2f}"
            after = "–" if excursion.error_after_m is None else f"{excursion.error_after_m:.2f}"
            ax.annotate(
                f"{estimate.name}: {end - start:.0f} s, {excursion.path_length_m:.0f} m: "
                f"{before} → {after} m",
                xy=(0.5 * (start + end), 1.0),
                xycoords=("data", "axes fraction"),
                ha="center",
                va="bottom",
                fontsize=7,
                color=_EXCURSION_COLOUR,
            )


def excursion_note(result: EvaluationResult) -> str:
    """Return the caption's sentence on excursions ("" without any)."""
    if not any(e.excursions for e in result.estimates):
        return ""
    return (
        f" Hatched bands are excursions: the reference lost for more than "
        f"{result.config.min_excursion_s:g} s while the estimate went on; the label gives "
        "their duration, the estimate's path outside and its error on leaving and on coming "
        "back."
    )
