"""The report's error series: ATE and RPE over time (with tracking gaps), and the error CDF."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from exporters.plots.excursions import excursion_note, mark_excursions
from exporters.plots.figure import (
    DEFAULT_MAX_POINTS,
    ENVELOPE_DIVISOR,
    GAP_COLOUR,
    MIN_ERROR_AXIS,
    MIN_GAP_WIDTH_SHARE,
    NS_PER_S,
    TOLERANCE_COLOUR,
    ImageFormat,
    Plot,
    decimate_uniform,
    encode_plot,
    estimate_colour,
    new_figure,
    path_jumps,
    reference_losses,
    seconds_since,
    with_nan_breaks,
)
from exporters.plots.svg.axes import Axes
from exporters.plots.svg.canvas import Figure
from exporters.plots.svg.draw import Style
from loceval.core.arrays import BoolArray, FloatArray
from loceval.evaluation import EvaluationConfig, EvaluationResult
from loceval.metrics.pose_errors import ErrorSeries
from loceval.trajectory import Trajectory

__all__ = [
    "describe_rpe_step",
    "envelope",
    "plot_ate_over_time",
    "plot_error_cdf",
    "plot_rpe_over_time",
]


def _shade_gaps(ax: Axes, result: EvaluationResult, t0_ns: int) -> None:
    gaps = reference_losses(result)
    if not gaps:
        return
    spans = np.asarray(gaps, dtype=np.int64)
    starts = seconds_since(spans[:, 0], t0_ns)
    ends = seconds_since(spans[:, 1], t0_ns)
    # A 2 s gap in a 3 h recording is narrower than a pixel: draw every gap at least
    # 0.3 % of the time axis wide so it shows.
    total_s = float(result.reference.duration_s)
    min_width = MIN_GAP_WIDTH_SHARE * total_s
    centre = 0.5 * (starts + ends)
    half = 0.5 * np.maximum(ends - starts, min_width)
    ax.xspans(
        centre - half,
        centre + half,
        Style(colour=GAP_COLOUR, width=0.5, face=GAP_COLOUR, alpha=0.35),
        label="tracking loss (reference gap)",
    )


def envelope(
    times_s: FloatArray, values: FloatArray, jump: BoolArray, *, buckets: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per-bucket minimum, maximum and mean of a long series, for drawing it as a band.

    Consecutive samples fall into about ``buckets`` equal buckets; a bucket never spans a
    break (tracking loss, :func:`loceval.core.gaps.path_breaks`), and a NaN row separates the
    stretches on either side of a break, so the band breaks there.

    Args:
        times_s: (N,) sample times, seconds.
        values: (N,) the series.
        jump: (N - 1,) True after each sample that ends a stretch.
        buckets: about how many buckets to make.

    Returns:
        ``(t, lo, hi, mean)``: bucket centre times, minima, maxima and means, (B,) each
        with NaN rows at the gaps.
    """
    n = int(values.shape[0])
    size = max(1, -(-n // max(buckets, 1)))
    stretch = np.concatenate(([0], np.cumsum(jump, dtype=np.int64)))
    stretch_start = np.concatenate(([0], np.flatnonzero(jump) + 1))
    local = np.arange(n, dtype=np.int64) - stretch_start[stretch]
    key = stretch * (n + 1) + local // size
    starts = np.flatnonzero(np.concatenate(([True], np.diff(key) != 0)))
    ends = np.concatenate((starts[1:], [n])) - 1
    lo = np.minimum.reduceat(values, starts)
    hi = np.maximum.reduceat(values, starts)
    mean = np.add.reduceat(values, starts) / (ends - starts + 1)
    centre = 0.5 * (times_s[starts] + times_s[ends])
    breaks = np.flatnonzero(np.diff(stretch[starts]) != 0) + 1
    out_t: FloatArray = np.insert(centre, breaks, np.nan)
    out_lo: FloatArray = np.insert(lo, breaks, np.nan)
    out_hi: FloatArray = np.insert(hi, breaks, np.nan)
    out_mean: FloatArray = np.insert(mean, breaks, np.nan)
    return out_t, out_lo, out_hi, out_mean


def _draw_series(
    ax: Axes,
    result: EvaluationResult,
    series: ErrorSeries,
    k: int,
    *,
    t0_ns: int,
    max_points: int,
) -> None:
    name = result.estimates[k].name or f"estimate {k + 1}"
    colour = estimate_colour(k)
    times = seconds_since(series.stamps_ns, t0_ns)
    if len(series) <= max_points:
        t, v = with_nan_breaks(
            [times, series.values],
            path_jumps(result, series.stamps_ns),
            np.arange(len(series), dtype=np.intp),
        )
        ax.line(t, v, Style(colour=colour, width=0.8), label=name)
        return
    # Too many samples to draw one by one: a light band between each bucket's smallest and
    # largest error (every peak survives) under a line of the bucket means. At print
    # resolution it shows what the zigzag line would, stays readable where estimates
    # overlap, and is two light paths instead of thousands of overlapping strokes.
    t, lo, hi, mean = envelope(
        times,
        series.values,
        path_jumps(result, series.stamps_ns),
        buckets=max_points // ENVELOPE_DIVISOR,
    )
    ax.band(t, lo, hi, Style(colour=None, width=0.0, face=colour, alpha=0.3))
    ax.line(t, mean, Style(colour=colour, width=0.9), label=name)


def _time_plot(
    result: EvaluationResult,
    rows: list[tuple[str, list[ErrorSeries | None]]],
    *,
    tolerance_row: int | None,
    max_points: int,
) -> Figure:
    t0_ns = int(result.reference.stamps_ns[0])
    fig = new_figure(1.2 + 1.45 * len(rows))
    axes = fig.subplots(len(rows), sharex=True)
    for r, (label, series_list) in enumerate(rows):
        ax = axes[r]
        _shade_gaps(ax, result, t0_ns)
        if r == 0:
            mark_excursions(ax, result, t0_ns)
        for k, series in enumerate(series_list):
            if series is not None:
                _draw_series(ax, result, series, k, t0_ns=t0_ns, max_points=max_points)
        tol = result.config.tolerance
        if r == tolerance_row and tol is not None:
            ax.hline(
                tol.distance_m,
                Style(colour=TOLERANCE_COLOUR, width=1.0, dash="dashed"),
                label=f"tolerance {tol.distance_m:g} m",
            )
        ax.ylabel = label
        # A floor on the axis range: rounding noise (1e-14 °) must not look like an error.
        ax.set_ylim(0.0, at_least=MIN_ERROR_AXIS)
        if r == 0:
            fig.legend_above(ax)
    axes[-1].xlabel = time_axis_label(result.reference)
    return fig


def time_axis_label(reference: Trajectory) -> str:
    """Return the x label of a plot over time: seconds, or pose numbers without times.

    A reference without times (a KITTI file without its times file) is stamped 0, 1, 2 s
    by its pose numbers, so its axis counts poses, not seconds.
    """
    if reference.indexed:
        return "pose number since the start of the reference (the reference has no times)"
    return "time since the start of the reference [s]"


def _time_plot_notes(
    result: EvaluationResult,
    rows: list[tuple[str, list[ErrorSeries | None]]],
    max_points: int,
) -> str:
    """The caption's explanation of what is drawn, only for what is in the figure."""
    notes = ""
    gaps = reference_losses(result)
    if gaps:
        notes += " Grey bands are tracking loss of the reference (not evaluated)"
        min_width_ns = MIN_GAP_WIDTH_SHARE * result.reference.duration_s * NS_PER_S
        notes += (
            "; short ones are drawn wider so they show."
            if any(b - a < min_width_ns for a, b in gaps)
            else "."
        )
    notes += excursion_note(result)
    series = [s for _, row in rows for s in row if s is not None]
    if any(bool(path_jumps(result, s.stamps_ns).any()) for s in series):
        notes += (
            " A break in a line is a stretch without evaluated poses (tracking loss of the "
            "reference, or of the estimate: longer than five of its own median intervals "
            f"and than {result.config.max_gap_s:g} s)."
        )
    if any(len(s) > max_points for s in series):
        notes += (
            " Long series are drawn as a light band from the smallest to the largest error "
            "of each time slice, with a line through the slice means."
        )
    return notes


def plot_ate_over_time(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """ATE (translation, and rotation when known) over time with tracking loss shaded."""
    rows: list[tuple[str, list[ErrorSeries | None]]] = [
        ("ATE [m]", [e.ate_translation for e in result.estimates])
    ]
    if any(e.ate_rotation is not None for e in result.estimates):
        rows.append(("ATE rotation [°]", [e.ate_rotation for e in result.estimates]))
    fig = _time_plot(result, rows, tolerance_row=0, max_points=max_points)
    return encode_plot(
        fig,
        formats,
        key="ate_time",
        title="Absolute trajectory error over time",
        caption=(
            "Distance between each aligned estimate pose and the ground truth at the same "
            "time." + _time_plot_notes(result, rows, max_points)
        ),
    )


def plot_rpe_over_time(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """RPE (translation, and rotation when known) over time with tracking loss shaded."""
    rows: list[tuple[str, list[ErrorSeries | None]]] = [
        ("RPE [m]", [e.rpe_translation for e in result.estimates])
    ]
    if any(e.rpe_rotation is not None for e in result.estimates):
        rows.append(("RPE rotation [°]", [e.rpe_rotation for e in result.estimates]))
    fig = _time_plot(result, rows, tolerance_row=None, max_points=max_points)
    cfg = result.config
    return encode_plot(
        fig,
        formats,
        key="rpe_time",
        title="Relative pose error over time",
        caption=(
            f"Error of the motion over each step of {describe_rpe_step(cfg)}, at the step's "
            "start." + _time_plot_notes(result, rows, max_points)
        ),
    )


def plot_error_cdf(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """Cumulative distribution of ATE with the thresholds (the reference-system paper's Fig. 7)."""
    fig = new_figure(4.0)
    (ax,) = fig.subplots()
    thresholds = result.config.thresholds_m
    for k, e in enumerate(result.estimates):
        values, shares = e.ate_translation.cdf()
        kept = decimate_uniform(values.size, max_points)
        ax.step(
            values[kept],
            100.0 * shares[kept],
            Style(colour=estimate_colour(k), width=1.2),
            label=e.name or f"estimate {k + 1}",
        )
        within = [t for t in thresholds if t in e.within]
        ax.markers(
            np.array(within),
            np.array([100.0 * e.within[t] for t in within]),
            Style(colour=None, face=estimate_colour(k)),
            size_pt=4.0,
        )
    for t in thresholds:
        ax.vline(t, Style(colour="#616161", width=1.0, dash="dotted"))
    tol = result.config.tolerance
    if tol is not None:
        ax.markers(
            np.array([tol.distance_m]),
            np.array([100.0 * tol.share]),
            Style(colour=None, face=TOLERANCE_COLOUR),
            shape="P",
            size_pt=9.0,
            label=f"tolerance: {tol}",
            z=5,
        )
    ax.set_xlim(0.0)
    ax.set_ylim(0.0, 101.0)
    _label_thresholds(ax, thresholds)
    ax.xlabel, ax.ylabel = "ATE [m]", "poses with error ≤ x [%]"
    ax.legend("lower right")
    caption = (
        "Share of poses whose error is at most the value on the x-axis; dotted lines are the "
        "thresholds, dots the shares within them."
    )
    if tol is not None:
        caption += " An estimate meets the tolerance when its curve passes above the red cross."
    return encode_plot(
        fig,
        formats,
        key="error_cdf",
        title="Error distribution (CDF)",
        caption=caption,
    )


_LABEL_GAP_AXES = 0.08  # threshold labels closer than this share of the axis stack up
_LABEL_ROWS = 3


def _label_thresholds(ax: Axes, thresholds: Sequence[float]) -> None:
    """Label the threshold lines above the axes, stacking labels that would overlap.

    Each label goes on the lowest of three rows where it keeps 8 % of the axis width from
    the previous label on that row; a label with no room (or outside the axis) is left out,
    its dotted line stays.
    """
    ax.settle_limits()  # the labels go where the thresholds lie on the x axis as it will be
    lo, hi = ax.view_x
    last = [-1.0] * _LABEL_ROWS
    for t in sorted(thresholds):  # a handful of thresholds
        frac = (t - lo) / (hi - lo) if hi > lo else 0.0
        if not 0.0 <= frac <= 1.0:
            continue
        row = next((r for r in range(_LABEL_ROWS) if frac - last[r] >= _LABEL_GAP_AXES), None)
        if row is None:
            continue
        last[row] = frac
        ax.text(
            t,
            1.0,
            f"{t:g} m",
            coords=("data", "axes"),
            offset_pt=(0.0, 2.0 + 9.0 * row),
            size_pt=7.0,
            colour="#424242",
        )


def describe_rpe_step(config: EvaluationConfig) -> str:
    """Return the RPE step in words: ``1 frame``, ``5 frames``, ``0.5 m``, ``1 s``."""
    delta, unit = config.rpe_delta, config.rpe_unit.value
    if unit == "frames":
        return f"{delta:g} frame{'' if delta == 1 else 's'}"
    return f"{delta:g} {unit}"
