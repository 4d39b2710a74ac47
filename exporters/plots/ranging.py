"""The ranging plots of the report: error against true distance, error over time, the plan.

Drawn only for an evaluation positioned from radio ranges (``result.ranging`` is set).
Errors are measured minus true distance, metres (non-line-of-sight errors are positive).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from exporters.plots.figure import (
    DEFAULT_MAX_POINTS,
    REFERENCE_COLOUR,
    TOLERANCE_COLOUR,
    ImageFormat,
    Plot,
    decimate_uniform,
    encode_plot,
    seconds_since,
)
from exporters.plots.mpl import new_figure, style_axes
from loceval.evaluation import EvaluationResult

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from loceval.radio.ranging import RangingResult

__all__ = ["plot_ranging"]

_POINT_COLOUR = "#546e7a"
_BIN_COLOUR = "#1565c0"


def plot_ranging(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> tuple[Plot, ...]:
    """Return the ranging plots (none when the evaluation has no ranging part)."""
    ranging = result.ranging
    if ranging is None:
        return ()
    return (
        _error_vs_distance(ranging, max_points=max_points, formats=formats),
        _error_over_time(result, ranging, max_points=max_points, formats=formats),
        _anchors_on_plan(result, ranging, max_points=max_points, formats=formats),
    )


def _threshold_lines(ax: Axes, ranging: RangingResult) -> None:
    for sign in (-1.0, 1.0):
        ax.axhline(
            sign * ranging.outlier_threshold_m, color=TOLERANCE_COLOUR, linestyle=":", linewidth=1.0
        )
    ax.axhline(0.0, color="#424242", linewidth=0.8)


def _error_vs_distance(
    ranging: RangingResult, *, max_points: int, formats: Sequence[ImageFormat]
) -> Plot:
    fig = new_figure(3.6)
    ax = fig.add_subplot()
    errors = ranging.errors.values
    kept = decimate_uniform(errors.size, max_points)
    ax.plot(
        ranging.true_distance_m[kept],
        errors[kept],
        linestyle="none",
        marker=".",
        markersize=2,
        color=_POINT_COLOUR,
        alpha=0.5,
        label="ranges",
        rasterized=kept.size > max_points // 2,
    )
    bins = ranging.distance_bins
    centres = [(b.start_m + b.end_m) / 2 for b in bins]
    ax.errorbar(
        centres,
        [b.bias_m for b in bins],
        yerr=[b.std_m for b in bins],
        color=_BIN_COLOUR,
        marker="o",
        markersize=4,
        capsize=2,
        linewidth=1.2,
        label="bias ± std per bin",
    )
    _threshold_lines(ax, ranging)
    ax.set_xlabel("true distance [m]")
    ax.set_ylabel("range error [m]")
    style_axes(ax)
    ax.legend(loc="upper left", fontsize=8, frameon=True, framealpha=0.9)
    width = bins[0].end_m - bins[0].start_m if bins else 0.0
    return encode_plot(
        fig,
        formats,
        key="ranging_distance",
        title="Range error against true distance",
        caption=(
            f"Every evaluated range (measured minus true distance) and the bias ± standard "
            f"deviation per {width:g} m bin; dotted lines are the outlier threshold "
            f"(± {ranging.outlier_threshold_m:g} m)."
        ),
    )


def _error_over_time(
    result: EvaluationResult,
    ranging: RangingResult,
    *,
    max_points: int,
    formats: Sequence[ImageFormat],
) -> Plot:
    fig = new_figure(3.2)
    ax = fig.add_subplot()
    errors = ranging.errors
    kept = decimate_uniform(errors.values.size, max_points)
    t_s = seconds_since(errors.stamps_ns[kept], int(result.reference.stamps_ns[0]))
    ax.plot(
        t_s,
        errors.values[kept],
        linestyle="none",
        marker=".",
        markersize=2,
        color=_POINT_COLOUR,
        alpha=0.6,
        rasterized=kept.size > max_points // 2,
    )
    _threshold_lines(ax, ranging)
    ax.set_xlabel("time since the reference's first pose [s]")
    ax.set_ylabel("range error [m]")
    style_axes(ax)
    return encode_plot(
        fig,
        formats,
        key="ranging_time",
        title="Range error over time",
        caption="Every evaluated range's error against its time; dotted lines are the outlier "
        "threshold.",
    )


def _anchors_on_plan(
    result: EvaluationResult,
    ranging: RangingResult,
    *,
    max_points: int,
    formats: Sequence[ImageFormat],
) -> Plot:
    fig = new_figure(4.5)
    ax = fig.add_subplot()
    xy = result.reference.positions_xyz[:, :2]
    kept = decimate_uniform(xy.shape[0], max_points)
    ax.plot(xy[kept, 0], xy[kept, 1], color=REFERENCE_COLOUR, linewidth=1.0, label="ground truth")
    used = np.array([a.position_xyz[:2] for a in ranging.anchors]).reshape(-1, 2)
    rmse = np.array([a.stats.rmse_m for a in ranging.anchors])
    points = ax.scatter(
        used[:, 0], used[:, 1], c=rmse, cmap="viridis", marker="^", s=40, zorder=3, label="anchor"
    )
    fig.colorbar(points, ax=ax, label="range RMSE [m]", shrink=0.8, use_gridspec=False)
    for anchor in ranging.anchors:
        ax.annotate(
            anchor.id,
            anchor.position_xyz[:2],
            fontsize=7,
            xytext=(3, 3),
            textcoords="offset points",
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    style_axes(ax)
    ax.legend(loc="best", fontsize=8, frameon=True, framealpha=0.9)
    unused = ", ".join(ranging.unused_anchors)
    caption = "The path from above and the anchors heard, coloured by their range RMSE."
    if unused:
        caption += f" Never heard (not drawn): {unused}."
    return encode_plot(
        fig, formats, key="ranging_plan", title="Anchors on the plan", caption=caption
    )
