"""Excursions in the report's time plots: stretches outside the tracked room, labelled.

An excursion (:mod:`loceval.metrics.excursions`) is a reference loss longer than the minimum while
an estimate went on; the time plots draw each as a hatched band over the grey tracking-loss
band, with the drift it measured written above it ("45 s, 38 m: 0.02 -> 0.21 m").
"""

from __future__ import annotations

from typing import Final

import numpy as np

from exporters.plots.figure import seconds_since
from exporters.plots.svg.axes import Axes
from exporters.plots.svg.draw import Style
from loceval.evaluation import EvaluationResult

__all__ = ["excursion_note", "mark_excursions"]

_EXCURSION_COLOUR: Final = "#6a1b9a"
_HATCHED: Final = Style(colour=_EXCURSION_COLOUR, width=0.6, hatch=_EXCURSION_COLOUR)


def mark_excursions(ax: Axes, result: EvaluationResult, t0_ns: int) -> None:
    """Draw every estimate's excursions as hatched, labelled bands (one per stretch)."""
    seen: set[tuple[int, int]] = set()
    for estimate in result.estimates:
        for excursion in estimate.excursions:  # a few stretches per run
            key = (excursion.start_ns, excursion.end_ns)
            start, end = seconds_since(np.array(key, dtype=np.int64), t0_ns).tolist()
            if key not in seen:
                ax.xspans(
                    np.array([start]),
                    np.array([end]),
                    _HATCHED,
                    label="excursion (outside the tracked room)" if not seen else None,
                    z=1.2,
                )
                seen.add(key)
            before = "–" if excursion.error_before_m is None else f"{excursion.error_before_m:.2f}"
            after = "–" if excursion.error_after_m is None else f"{excursion.error_after_m:.2f}"
            ax.text(
                0.5 * (start + end),
                1.0,
                f"{estimate.name}: {end - start:.0f} s, {excursion.path_length_m:.0f} m: "
                f"{before} → {after} m",
                coords=("data", "axes"),
                offset_pt=(0.0, 1.0),
                size_pt=7.0,
                colour=_EXCURSION_COLOUR,
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
