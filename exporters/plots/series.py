"""The report's error series: ATE and RPE over time (with tracking gaps), and the error CDF."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

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
    keep_every_vertex,
    legend_above,
    new_figure,
    path_jumps,
    reference_losses,
    seconds_since,
    style_axes,
    with_nan_breaks,
)
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
    starts, ends = centre - half, centre + half
    boxes = np.stack(
        [
            np.stack([starts, np.zeros_like(starts)], axis=1),
            np.stack([starts, np.ones_like(starts)], axis=1),
            np.stack([ends, np.ones_like(starts)], axis=1),
            np.stack([ends, np.zeros_like(starts)], axis=1),
        ],
        axis=1,
    )
    ax.add_collection(
        PolyCollection(
            list(boxes),
            transform=ax.get_xaxis_transform(),
            facecolors=GAP_COLOUR,
            edgecolors=GAP_COLOUR,
            alpha=0.35,
            linewidths=0.5,
            label="tracking loss (reference gap)",
        ),
        autolim=False,
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
        keep_every_vertex(ax.plot(t, v, color=colour, linewidth=0.8, label=name))
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
    ax.fill_between(t, lo, hi, color=colour, alpha=0.3, linewidth=0.0)
    ax.plot(t, mean, color=colour, linewidth=0.9, label=name)


def _time_plot(
    result: EvaluationResult,
    rows: list[tuple[str, list[ErrorSeries | None]]],
    *,
    tolerance_row: int | None,
    max_points: int,
) -> Figure:
    t0_ns = int(result.reference.stamps_ns[0])
    fig = new_figure(1.2 + 1.45 * len(rows))
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
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
            ax.axhline(
                tol.distance_m,
                color=TOLERANCE_COLOUR,
                linestyle="--",
                linewidth=1.0,
                label=f"tolerance {tol.distance_m:g} m",
            )
        ax.set_ylabel(label)
        # A floor on the axis range: rounding noise (1e-14 °) must not look like an error.
        ax.set_ylim(0.0, max(ax.get_ylim()[1], MIN_ERROR_AXIS))
        style_axes(ax)
        if r == 0:
            legend_above(fig, ax)
    axes[-1].set_xlabel(time_axis_label(result.reference))
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
    ax = fig.add_subplot()
    thresholds = result.config.thresholds_m
    for k, e in enumerate(result.estimates):
        values, shares = e.ate_translation.cdf()
        kept = decimate_uniform(values.size, max_points)
        ax.step(
            values[kept],
            100.0 * shares[kept],
            where="post",
            color=estimate_colour(k),
            linewidth=1.2,
            label=e.name or f"estimate {k + 1}",
        )
        shares_at = [100.0 * e.within[t] for t in thresholds if t in e.within]
        ax.plot(
            [t for t in thresholds if t in e.within],
            shares_at,
            linestyle="none",
            marker="o",
            markersize=4,
            color=estimate_colour(k),
        )
    for t in thresholds:
        ax.axvline(t, color="#616161", linestyle=":", linewidth=1.0)
    tol = result.config.tolerance
    if tol is not None:
        ax.plot(
            [tol.distance_m],
            [100.0 * tol.share],
            marker="P",
            markersize=9,
            color=TOLERANCE_COLOUR,
            linestyle="none",
            label=f"tolerance: {tol}",
            zorder=5,
        )
    ax.set_xlim(left=0.0)
    ax.set_ylim(0.0, 101.0)
    _label_thresholds(ax, thresholds)
    ax.set_xlabel("ATE [m]")
    ax.set_ylabel("poses with error ≤ x [%]")
    style_axes(ax)
    ax.legend(loc="lower right", fontsize=8, frameon=True, framealpha=0.9)
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
    lo, hi = ax.get_xlim()
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
            1.01 + 0.055 * row,
            f"{t:g} m",
            transform=ax.get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize=7,
            color="#424242",
        )


def describe_rpe_step(config: EvaluationConfig) -> str:
    """Return the RPE step in words: ``1 frame``, ``5 frames``, ``0.5 m``, ``1 s``."""
    delta, unit = config.rpe_delta, config.rpe_unit.value
    if unit == "frames":
        return f"{delta:g} frame{'' if delta == 1 else 's'}"
    return f"{delta:g} {unit}"
