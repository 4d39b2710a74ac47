"""The report's clock plot: the motion correlation against the time offset, per estimate."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from exporters.plots.figure import (
    DEFAULT_MAX_POINTS,
    ImageFormat,
    Plot,
    decimate_minmax,
    encode_plot,
    estimate_colour,
    legend_above,
    new_figure,
    style_axes,
)
from loceval.evaluation import EvaluationResult

__all__ = ["ZOOM_S", "plot_clock_correlation"]

ZOOM_S = 1.0
"""Half-width of the lower panel around each estimate's offset, seconds."""


def plot_clock_correlation(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot | None:
    """Correlation of the motions at every time offset searched, and near the one found.

    Args:
        result: the evaluation.
        max_points: most vertices per curve (each bucket's highest and lowest survive).
        formats: the encodings to produce.

    Returns:
        The plot, or None when no estimate's clock was checked.
    """
    checked = [
        (k, e.offsets.time_offset)
        for k, e in enumerate(result.estimates)
        if e.offsets is not None and e.offsets.time_offset is not None
    ]
    if not checked:
        return None
    fig = new_figure(5.0)
    full, zoom = fig.subplots(2, 1)
    for k, clock in checked:
        colour = estimate_colour(k)
        name = result.estimates[k].name or f"estimate {k + 1}"
        scores = clock.scores
        kept = decimate_minmax(np.nan_to_num(scores, nan=-1.0), max_points)
        full.plot(clock.lags_s[kept], scores[kept], color=colour, linewidth=1.0, label=name)
        found = clock.estimated_s if clock.estimated_s is not None else clock.value_s
        near = np.abs(clock.lags_s - found) <= ZOOM_S
        zoom.plot(
            (clock.lags_s[near] - found) * 1e3,
            scores[near],
            color=colour,
            linewidth=1.2,
            marker=".",
            markersize=3,
        )
        for candidate in clock.candidates_s:
            full.axvline(candidate, color=colour, linestyle=":", linewidth=0.8)
    zoom.axvline(0.0, color="#616161", linestyle=":", linewidth=1.0)
    full.set_xlabel("time offset added to the estimate's stamps [s]")
    zoom.set_xlabel("time offset minus the one found [ms]")
    for ax in (full, zoom):
        ax.set_ylabel("correlation")
        style_axes(ax)
    legend_above(fig, full)
    caption = (
        "Correlation of the motion signals (angular speed, or speed for position-only "
        "systems) at every time offset where the recordings overlap; dotted lines mark the "
        f"offsets that fit (more than one when the motion repeats). Below: ±{ZOOM_S:g} s "
        "around the one found, whose refined value is at 0."
    )
    return encode_plot(
        fig, formats, key="clock_correlation", title="Clock check: correlation", caption=caption
    )
