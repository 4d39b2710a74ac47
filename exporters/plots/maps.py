"""The report's maps: the paths from above, each estimate's error along its path, side views."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from exporters.cad.building import FRAME_BUILDING_UP_TO
from exporters.colours import error_bins, hex_colour, scale_words
from exporters.plots.figure import (
    DEFAULT_MAX_POINTS,
    MAX_SPAN_MARKERS,
    REFERENCE_COLOUR,
    SIDE_VIEW_MIN_Z_SPAN_M,
    TOLERANCE_COLOUR,
    WIDTH_IN,
    ImageFormat,
    Plot,
    breaks_between,
    decimate_minmax,
    decimate_uniform,
    encode_plot,
    estimate_colour,
    new_figure,
    path_jumps,
    with_nan_breaks,
)
from exporters.plots.svg.axes import Axes
from exporters.plots.svg.canvas import ColourBar
from exporters.plots.svg.draw import Style
from exporters.plots.underlay import draw_floor_plan, floor_plan_note
from loceval.core.arrays import FloatArray
from loceval.evaluation import EstimateResult, EvaluationResult
from loceval.trajectory import Trajectory

__all__ = [
    "failing_span_markers",
    "is_3d",
    "plot_ate_path",
    "plot_overlay_xy",
    "plot_side_views",
]


def _paths_xy(result: EvaluationResult) -> FloatArray:
    """Return (N, 2) every path's x-y (the reference and the aligned estimates)."""
    xy = [result.reference.positions_xyz[:, :2]]
    xy.extend(e.aligned.positions_xyz[:, :2] for e in result.estimates)
    return np.concatenate(xy)


def _xy_figure_height(
    result: EvaluationResult, *, plot_width_in: float, floor_plan: FloatArray | None = None
) -> float:
    """Height for an equal-aspect x-y plot of the paths (and a framed building)."""
    xy = _paths_xy(result)
    if floor_plan is not None and len(floor_plan) and len(xy):
        ends = floor_plan.reshape(-1, 2)
        paths_size = max(float(np.linalg.norm(np.ptp(xy, axis=0))), 1.0)
        if float(np.linalg.norm(np.ptp(ends, axis=0))) <= FRAME_BUILDING_UP_TO * paths_size:
            xy = np.concatenate([xy, ends])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    dx, dy = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    ratio = 1.0 if dx <= 0 else dy / dx
    return float(np.clip(plot_width_in * ratio, 2.6, 7.5)) + 1.2


def is_3d(result: EvaluationResult) -> bool:
    """Whether the side views are worth drawing: the reference's heights span > 5 cm."""
    z = result.reference.positions_xyz[:, 2]
    return bool(z.size) and float(np.ptp(z)) > SIDE_VIEW_MIN_Z_SPAN_M


def failing_span_markers(estimate: EstimateResult) -> list[tuple[int, float, float]]:
    """Return ``(number, x, y)`` of the worst failing stretches, numbered as in the verdict."""
    if estimate.verdict is None:
        return []
    spans = estimate.verdict.failing_spans[:MAX_SPAN_MARKERS]
    return [
        (k, span.max_error_position_xyz[0], span.max_error_position_xyz[1])
        for k, span in enumerate(spans, start=1)
    ]


def _draw_reference_xy(
    ax: Axes,
    result: EvaluationResult,
    max_points: int,
    axes_ij: tuple[int, int] = (0, 1),
    *,
    on_top: bool = False,
) -> None:
    a, b = _drawn_axes(result, result.reference, axes_ij, max_points)
    # Under an error-coloured path the truth is a wide band; over noisy estimates it is
    # drawn last and thinner, so it stays visible.
    ax.line(
        a,
        b,
        Style(colour=REFERENCE_COLOUR, width=1.5 if on_top else 2.2),
        z=4 if on_top else 2,
        label=_reference_label(result),
    )


def _drawn_axes(
    result: EvaluationResult, path: Trajectory, axes_ij: tuple[int, int], max_points: int
) -> list[FloatArray]:
    """Return the path's two coordinates ``axes_ij``, decimated, NaN where the path breaks."""
    kept = decimate_uniform(len(path), max_points)
    return with_nan_breaks(
        [path.positions_xyz[:, axes_ij[0]], path.positions_xyz[:, axes_ij[1]]],
        path_jumps(result, path.stamps_ns),
        kept,
    )


def _reference_label(result: EvaluationResult) -> str:
    name = result.reference.name or "reference"
    return f"{name} (ground truth)"


def _draw_estimate(
    ax: Axes,
    result: EvaluationResult,
    k: int,
    max_points: int,
    axes_ij: tuple[int, int] = (0, 1),
) -> None:
    e = result.estimates[k]
    a, b = _drawn_axes(result, e.aligned, axes_ij, max_points)
    ax.line(
        a,
        b,
        Style(colour=estimate_colour(k), width=1.0, alpha=0.85),
        label=e.name or f"estimate {k + 1}",
    )


def _mark_start(ax: Axes, result: EvaluationResult) -> None:
    start = result.reference.positions_xyz[0]
    ax.markers(
        start[:1],
        start[1:2],
        Style(colour="#000000", width=1.0, face="#ffffff"),
        size_pt=7.0,
        label="start",
        z=5,
    )


def plot_overlay_xy(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
    floor_plan: FloatArray | None = None,
) -> Plot:
    """Top-down (x-y) overlay of the reference and every aligned estimate.

    ``floor_plan`` (see :func:`exporters.plots.underlay.floor_plan_segments`) is drawn
    under the paths in light grey.
    """
    fig = new_figure(_xy_figure_height(result, plot_width_in=WIDTH_IN - 0.8, floor_plan=floor_plan))
    (ax,) = fig.subplots()
    building = draw_floor_plan(ax, floor_plan, _paths_xy(result))
    _draw_reference_xy(ax, result, max_points, on_top=True)
    for k in range(len(result.estimates)):
        _draw_estimate(ax, result, k, max_points)
    _mark_start(ax, result)
    ax.equal = True
    ax.xlabel, ax.ylabel = "x [m]", "y [m]"
    fig.legend_above(ax)
    names = ", ".join(e.name or f"estimate {k + 1}" for k, e in enumerate(result.estimates))
    return encode_plot(
        fig,
        formats,
        key="overlay_xy",
        title="Paths from above (x-y)",
        caption=(
            f"The ground truth in cyan and the aligned estimates ({names}) seen from "
            "above; the circle marks the start."
        )
        + floor_plan_note(building),
    )


def plot_ate_path(
    result: EvaluationResult,
    index: int,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
    floor_plan: FloatArray | None = None,
) -> Plot:
    """Top-down path of one estimate coloured by its ATE, with failing stretches numbered.

    ``floor_plan`` is drawn under the path in light grey, as in :func:`plot_overlay_xy`.
    """
    e = result.estimates[index]
    name = e.name or f"estimate {index + 1}"
    ate = e.ate_translation.values
    kept = decimate_minmax(ate, max_points)
    xy = e.aligned.positions_xyz[kept, :2]
    segments = np.stack([xy[:-1], xy[1:]], axis=1)
    keep_segment = ~breaks_between(path_jumps(result, e.aligned.stamps_ns), kept)
    # Each drawn segment takes the larger error of its two ends, so a peak shows.
    seg_err = np.maximum(ate[kept][:-1], ate[kept][1:])
    # The one ATE colour scale of every output (viewer, DXF, .3dm, GLB, IFC): anchored to
    # the tolerance when there is one.
    bins = error_bins(result)
    inner = [b.high_m for b in bins[:-1]]
    top = max([1.5 * inner[-1]] if inner else [1.0])
    top = max(top, float(ate.max()) if ate.size else 0.0)
    bounds = [0.0, *inner, top]
    tolerance = e.verdict.tolerance.distance_m if e.verdict is not None else None
    fig = new_figure(_xy_figure_height(result, plot_width_in=WIDTH_IN - 1.8, floor_plan=floor_plan))
    (ax,) = fig.subplots()
    building = draw_floor_plan(ax, floor_plan, _paths_xy(result))
    _draw_reference_xy(ax, result, max_points)
    # each segment in its bin's colour (the bins' upper bounds, increasing)
    classes = np.searchsorted(np.asarray(inner), seg_err[keep_segment], side="right")
    ax.segments(
        segments[keep_segment], classes, [hex_colour(b.color_rgb) for b in bins], width=1.8, z=3
    )
    ax.x.add(xy[:, 0])
    ax.y.add(xy[:, 1])
    fig.colour_bar(
        ax,
        ColourBar(
            bounds=bounds,
            colours=[hex_colour(b.color_rgb) for b in bins],
            # the caption says what the colours mean (the tolerance in words)
            label="ATE [m]" if tolerance is not None else "ATE [m] (bins as in the CAD files)",
            marker=tolerance,
            marker_label="tolerance",
        ),
    )
    for number, x, y in failing_span_markers(e):
        ax.text(
            x,
            y,
            str(number),
            offset_pt=(9.0, 9.0),
            size_pt=8.0,
            bold=True,
            circle=TOLERANCE_COLOUR,
        )
    ax.equal = True
    ax.xlabel, ax.ylabel = "x [m]", "y [m]"
    caption = (
        f"{name}'s aligned path coloured by its absolute trajectory error (ATE) at each "
        f"pose, over the ground truth in cyan. {scale_words(result)}"
    )
    if tolerance is not None and e.verdict is not None and e.verdict.failing_spans:
        caption += (
            " Numbered circles mark where the worst stretches beyond the tolerance peak "
            "(see the verdict)."
        )
    caption += floor_plan_note(building)
    return encode_plot(
        fig,
        formats,
        key=f"ate_path_{index}",
        title=f"{name}: error along the path",
        caption=caption,
    )


def plot_side_views(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """Side views (x-z and y-z) of the reference and every aligned estimate."""
    fig = new_figure(5.2)
    axes = fig.subplots(2)
    for ax, (i, label) in zip(axes, ((0, "x"), (1, "y")), strict=True):
        _draw_reference_xy(ax, result, max_points, axes_ij=(i, 2), on_top=True)
        for k in range(len(result.estimates)):
            _draw_estimate(ax, result, k, max_points, axes_ij=(i, 2))
        ax.xlabel, ax.ylabel = f"{label} [m]", "z [m]"
    fig.legend_above(axes[0])
    return encode_plot(
        fig,
        formats,
        key="side_views",
        title="Side views (x-z, y-z)",
        caption=(
            "The paths seen from the side; the height axis is stretched to show height errors."
        ),
    )
