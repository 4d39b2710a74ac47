"""The report's clock plots, per estimate.

The motion correlation against the time offset, and the time offset along the run (the
clock's drift and steps).
"""

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
    new_figure,
)
from exporters.plots.svg.draw import Style
from loceval.calibration.clock import TimeOffsetEstimate
from loceval.calibration.drift import ClockDrift
from loceval.core.quantities import plus_minus
from loceval.evaluation import EvaluationResult

__all__ = ["ZOOM_S", "drift_checked", "plot_clock_correlation", "plot_clock_drift"]

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
    full, zoom = fig.subplots(2)
    for k, clock in checked:
        colour = estimate_colour(k)
        name = result.estimates[k].name or f"estimate {k + 1}"
        scores = clock.scores
        kept = decimate_minmax(np.nan_to_num(scores, nan=-1.0), max_points)
        full.line(clock.lags_s[kept], scores[kept], Style(colour=colour, width=1.0), label=name)
        found = clock.estimated_s if clock.estimated_s is not None else clock.value_s
        near = np.abs(clock.lags_s - found) <= ZOOM_S
        lags_ms, near_scores = (clock.lags_s[near] - found) * 1e3, scores[near]
        zoom.line(lags_ms, near_scores, Style(colour=colour, width=1.2))
        zoom.markers(lags_ms, near_scores, Style(colour=None, face=colour), size_pt=2.5)
        for candidate in clock.candidates_s:
            full.vline(candidate, Style(colour=colour, width=0.8, dash="dotted"))
    zoom.vline(0.0, Style(colour="#616161", width=1.0, dash="dotted"))
    full.xlabel = "time offset added to the estimate's stamps [s]"
    zoom.xlabel = "time offset minus the one found [ms]"
    full.ylabel = zoom.ylabel = "correlation"
    fig.legend_above(full)
    caption = (
        "Correlation of the motion signals (angular speed, or speed for position-only "
        "systems) at every time offset where the recordings overlap; dotted lines mark the "
        f"offsets that fit (more than one when the motion repeats). Below: ±{ZOOM_S:g} s "
        "around the one found, whose refined value is at 0."
    )
    return encode_plot(
        fig, formats, key="clock_correlation", title="Clock check: correlation", caption=caption
    )


def drift_checked(result: EvaluationResult) -> list[tuple[int, TimeOffsetEstimate, ClockDrift]]:
    """The estimates whose clock's drift was checked: (index, time offset, drift)."""
    out = []
    for k, e in enumerate(result.estimates):
        clock = None if e.offsets is None else e.offsets.time_offset
        if clock is not None and clock.drift is not None:
            out.append((k, clock, clock.drift))
    return out


def plot_clock_drift(
    result: EvaluationResult, *, formats: Sequence[ImageFormat] = ("svg",)
) -> Plot | None:
    """The time offset along the run: the windows' offsets, the fitted line and what was applied.

    One panel per estimate whose drift was checked. Its offsets are shown as their change
    from the fitted line's offset at the estimate's first pose, in ms, against minutes of
    the estimate's clock: the windows with 1-sigma bars (hollow where the line weighed them
    less), the fitted line with its steps, and, dashed, the change applied when it is not
    that line (the drift not applied).

    Args:
        result: the evaluation.
        formats: the encodings to produce.

    Returns:
        The plot, or None when no estimate's drift was checked.
    """
    checked = drift_checked(result)
    if not checked:
        return None
    fig = new_figure(1.2 + 1.6 * len(checked))
    axes = fig.subplots(len(checked))
    for ax, (k, clock, drift) in zip(axes, checked, strict=True):
        colour = estimate_colour(k)
        name = result.estimates[k].name or f"estimate {k + 1}"
        w = drift.windows
        base_s = drift.offset_s
        ok = np.isfinite(w.offset_s)
        minutes = w.centre_s / 60.0
        for used, face in ((True, colour), (False, "white")):
            sel = ok & (w.used == used)
            if sel.any():
                ax.errorbars(
                    minutes[sel],
                    (w.offset_s[sel] - base_s) * 1e3,
                    w.sigma_s[sel] * 1e3,
                    Style(colour=colour, width=0.8, face=face),
                    label=f"{name}: windows (1 sigma)" if used else "weighed less (outliers)",
                )
        t = np.linspace(0.0, drift.duration_s, 400)
        stamps = drift.epoch_ns + np.rint(t * 1e9).astype(np.int64)
        fitted = drift.model(with_rate=True, with_steps=True, offset_s=base_s)
        ax.line(
            t / 60.0,
            fitted.varying_s(stamps) * 1e3,
            Style(colour=colour, width=1.2),
            label="fitted: "
            + plus_minus(drift.rate_ppm, drift.sigma_rate_ppm, "ppm", sign=True)
            + (
                f", {len(drift.steps)} step{'s' if len(drift.steps) > 1 else ''}"
                if drift.steps
                else ""
            ),
        )
        applied = clock.model
        if applied.rate_ppm != drift.rate_ppm or len(applied.steps) != len(drift.steps):
            # The change applied along the run (its level is the time offset's business).
            ax.line(
                t / 60.0,
                applied.varying_s(stamps) * 1e3,
                Style(colour="#616161", width=1.0, dash="dashed"),
                label="applied" if applied.varies else "applied: a constant offset",
            )
        ax.ylabel = "offset change [ms]"
        ax.legend("best", size_pt=7.0)
    axes[-1].xlabel = "minutes along the run (the estimate's clock)"
    caption = (
        "The time offset measured in windows along the run, as its change from the fitted "
        "line's offset at the estimate's first pose: a clock that runs fast or slow makes a "
        "slope (1 ppm is 3.6 ms per hour), a clock step a jump. Bars are 1 sigma; hollow "
        "windows weighed less in the fit. Dashed: the change applied along the run, where "
        "it is not the fitted one (the drift not corrected)."
    )
    return encode_plot(
        fig, formats, key="clock_drift", title="Clock along the run", caption=caption
    )
