"""The control-point report's plan view: the points, and each visit's error as a scaled arrow.

Errors of centimetres on a grid of metres would vanish at true scale, so the arrows are
drawn ``scale`` times longer than the error; the scale is chosen so that the largest error
spans a third of the smallest point spacing (rounded to 1, 2 or 5 times a power of ten),
and a scale bar shows what length on the plan one error centimetre (or metre) is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes

from exporters.plots.figure import (
    ImageFormat,
    Plot,
    encode_plot,
    estimate_colour,
)
from exporters.plots.mpl import new_figure, style_axes
from exporters.plots.underlay import draw_floor_plan, floor_plan_note
from loceval.checkpoint_evaluation import CheckpointEvaluation
from loceval.core.arrays import FloatArray

__all__ = ["device_heights_m", "error_vector_scale", "plot_checkpoint_plan"]

_ARROW_SHARE = 1.0 / 3.0
"""The largest error's arrow spans this share of the smallest point spacing."""


def error_vector_scale(evaluation: CheckpointEvaluation) -> float:
    """Return the arrow scale: plan metres per error metre (1, 2 or 5 x 10^k, at least 1)."""
    largest = max((v.error_h_m for e in evaluation.estimates for v in e.result.visits), default=0.0)
    spacing = evaluation.points.min_spacing_m()
    if largest <= 0.0 or not math.isfinite(spacing):
        return 1.0
    raw = _ARROW_SHARE * spacing / largest
    if raw <= 1.0:
        return 1.0
    power = 10.0 ** math.floor(math.log10(raw))
    step = max((m for m in (1.0, 2.0, 5.0) if m * power <= raw), default=1.0)
    return step * power


def device_heights_m(evaluation: CheckpointEvaluation) -> FloatArray:
    """Return the device's heights at the visits (measured), else the control points'."""
    visits = [v for e in evaluation.estimates for v in e.result.visits]
    if not visits:
        heights: FloatArray = evaluation.points.positions_xyz[:, 2]
        return heights
    return np.array([v.measured_xyz[2] for v in visits])


def plot_checkpoint_plan(
    evaluation: CheckpointEvaluation,
    index: int,
    *,
    formats: Sequence[ImageFormat] = ("svg",),
    floor_plan: FloatArray | None = None,
) -> Plot:
    """Draw the plan (x-y) of the control points with one estimate's error arrows.

    Args:
        evaluation: the evaluation.
        index: which estimate.
        formats: the encodings to produce.
        floor_plan: the building's floor plan drawn under the points, (K, 2, 2) metres
            (see :func:`exporters.plots.underlay.floor_plan_segments`).

    Returns:
        The plot (key ``checkpoints-<index>``).
    """
    entry = evaluation.estimates[index]
    points = evaluation.points
    scale = error_vector_scale(evaluation)
    fig = new_figure(5.0)
    ax = fig.add_subplot()
    style_axes(ax)
    xy = points.positions_xyz[:, :2]
    building = draw_floor_plan(ax, floor_plan, xy)
    ax.scatter(xy[:, 0], xy[:, 1], s=14, marker="+", color="#212121", label="control point")
    visited = {v.point_id for v in entry.result.visits}
    if len(points) <= 60:
        for pid, (x, y) in zip(points.ids, xy.tolist(), strict=True):
            colour = "#212121" if pid in visited else "#c62828"
            ax.annotate(pid, (x, y), xytext=(3, 3), textcoords="offset points", fontsize=6,
                        color=colour)  # fmt: skip
    visits = entry.result.visits
    if visits:
        start = np.array([v.surveyed_xyz[:2] for v in visits])
        error = np.array([v.error_xyz[:2] for v in visits])
        aligned = np.array([v.used_for_alignment for v in visits])
        colour = estimate_colour(index)
        for mask, label, tone in ((~aligned, "error (scored)", colour),
                                  (aligned, "error (alignment point)", "#9e9e9e")):  # fmt: skip
            if mask.any():
                ax.quiver(
                    start[mask, 0], start[mask, 1], error[mask, 0] * scale,
                    error[mask, 1] * scale, angles="xy", scale_units="xy", scale=1.0,
                    color=tone, width=0.003, label=label,
                )  # fmt: skip
    _scale_bar(ax, scale, xy, points.min_spacing_m())
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper right", fontsize=7, frameon=False)
    name = entry.name or f"estimate {index + 1}"
    return encode_plot(
        fig,
        formats,
        key=f"checkpoints-{index}",
        title=f"Control points and the errors of {name} (plan, arrows x{scale:g})",
        caption=(
            f"Crosses: the surveyed points (red labels: never visited). Arrows: from the "
            f"surveyed point along the horizontal error of each visit, drawn {scale:g} times "
            "longer than the error; the bar shows the plan length of the error it names."
        )
        + floor_plan_note(building),
    )


def _scale_bar(ax: Axes, scale: float, points_xy: FloatArray, spacing_m: float) -> None:
    """Draw a bar of one round error length at the arrows' scale, below the points."""
    gap = spacing_m if math.isfinite(spacing_m) else 1.0
    target = gap / (2.0 * scale)
    power = 10.0 ** math.floor(math.log10(target))
    error_m = max((m * power for m in (1.0, 2.0, 5.0) if m * power <= target), default=power)
    text = f"{error_m * 100:g} cm error" if error_m < 1.0 else f"{error_m:g} m error"
    x0 = float(points_xy[:, 0].min())
    y0 = float(points_xy[:, 1].min()) - 0.6 * gap
    ax.plot([x0, x0 + error_m * scale], [y0, y0], color="#424242", linewidth=2.0)
    ax.annotate(text, (x0, y0), xytext=(0, 3), textcoords="offset points", fontsize=7,
                color="#424242", va="bottom")  # fmt: skip
