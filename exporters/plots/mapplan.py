"""The report's map figure: the robot's map on the building plan, wall cells by distance.

Drawn only when a map was measured (``result.map`` is set). Two panels: the map as placed
by the evaluation (the estimate's alignment) and after the best similarity fit; the plan's
walls in grey, each wall cell a dot coloured by its distance to the nearest plan wall (the
report's ATE colours and bins), clutter (not in the plan) in magenta.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import BoundaryNorm, ListedColormap

from exporters.colours import map_bins
from exporters.plots.figure import (
    DEFAULT_MAX_POINTS,
    ImageFormat,
    Plot,
    decimate_uniform,
    encode_plot,
)
from exporters.plots.mpl import new_figure, style_axes
from loceval.evaluation import EvaluationResult

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from loceval.core.arrays import FloatArray
    from loceval.maps import MapEvaluation

__all__ = ["MAP_FIGURE_KEY", "MAP_HISTORY_KEY", "plot_map", "plot_map_history"]

MAP_FIGURE_KEY: Final = "map_plan"
MAP_HISTORY_KEY: Final = "map_history"
_CLUTTER: Final = "#c2185b"
_PLAN_GREY: Final = "0.55"


def plot_map(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> tuple[Plot, ...]:
    """Return the map figure (none when no map was measured)."""
    found = result.map
    if found is None:
        return ()
    bins = map_bins(found.distance_m, result.config.thresholds_m)
    cmap = ListedColormap(["#{:02x}{:02x}{:02x}".format(*b.color_rgb) for b in bins])
    norm = BoundaryNorm([0.0, *(b.high_m for b in bins[:-1]), np.inf], cmap.N)
    fig = new_figure(4.2)
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    kept = decimate_uniform(len(found.cells_xy), max_points)
    similarity = found.similarity[0]
    panels = (
        ("as placed", found.cells_xy[kept], found.distance_m[kept], found.placed.rmse),
        (
            "after the similarity fit",
            similarity.apply(found.cells_xy[kept]),
            found.fitted_distance_m[kept],
            found.similarity[1].rmse,
        ),
    )
    clutter = found.clutter[kept]
    for ax, (title, xy, distance, rmse) in zip(axes, panels, strict=True):
        _draw(ax, found, xy, distance, clutter, cmap=cmap, norm=norm)
        ax.set_title(f"{title}: RMSE {rmse:.3f} m", fontsize=9)
    axes[0].set_ylabel("y [m]")
    lo = found.cells_xy.min(axis=0) - 1.0
    hi = found.cells_xy.max(axis=0) + 1.0
    axes[0].set_xlim(lo[0], hi[0])
    axes[0].set_ylim(lo[1], hi[1])
    labels = ", ".join(b.label for b in bins)
    fit = similarity.to_dict()
    return (
        encode_plot(
            fig,
            formats,
            key=MAP_FIGURE_KEY,
            title="The robot's map on the building plan",
            caption=(
                f"Grey: the plan's walls. Dots: the map's wall cells (occupied cells next to "
                f"free space), coloured by their distance to the nearest plan wall ({labels}); "
                f"magenta: clutter, farther than {found.clutter_m:g} m from every wall after the "
                f"fit ({found.clutter_cells} cells, left out of the figures). Left: placed by "
                f"{found.estimate or 'the given transform'}'s alignment; right: after the best "
                f"similarity fit (scale {fit['scale']:.4f}, {fit['rotation_deg']:+.2f}°: "
                f"{found.drift_sentence()})."
            ),
        ),
    )


def plot_map_history(
    result: EvaluationResult, *, formats: Sequence[ImageFormat] = ("svg",)
) -> tuple[Plot, ...]:
    """Return the map-over-time figure (none without two judged messages of a topic)."""
    found = result.map
    judged = [] if found is None else [s for s in found.history if s.placed_rmse_m is not None]
    if found is None or len(judged) < 2:
        return ()
    timed = all(s.t_s is not None for s in judged)
    x = np.array([s.t_s if timed else s.index for s in judged], dtype=np.float64)
    fig = new_figure(3.2)
    ax, scale_ax = fig.subplots(1, 2, sharex=True)
    for label, key, style in (
        ("as placed", "placed_rmse_m", "o-"),
        ("rigid fit", "rigid_rmse_m", "s--"),
        ("similarity fit", "similarity_rmse_m", "^:"),
    ):
        ax.plot(x, [getattr(s, key) for s in judged], style, markersize=3, label=label)
    ax.set_ylabel("wall distance RMSE [m]")
    ax.legend(fontsize=7)
    scale_ax.plot(x, [s.scale_error_pct for s in judged], "o-", markersize=3, color="#6a1b9a")
    scale_ax.axhline(0.0, color=_PLAN_GREY, linewidth=0.6)
    scale_ax.set_ylabel("length error [%]")
    for axis in (ax, scale_ax):
        style_axes(axis)
        axis.set_xlabel("t [s] since the reference's first stamp" if timed else "message")
    return (
        encode_plot(
            fig,
            formats,
            key=MAP_HISTORY_KEY,
            title="The map over time",
            caption=(
                f"Each of {len(judged)} map messages judged against the plan: the wall cells' "
                "RMSE as placed and after the best rigid and similarity fits (left), and how "
                "much longer (+) or shorter (-) than the plan the map is (right)."
            ),
        ),
    )


def _draw(
    ax: Axes,
    found: MapEvaluation,
    xy: FloatArray,
    distance: FloatArray,
    clutter: np.ndarray,
    *,
    cmap: ListedColormap,
    norm: BoundaryNorm,
) -> None:
    lines = LineCollection(list(found.plan_xy), colors=_PLAN_GREY, linewidths=0.7, zorder=1)
    ax.add_collection(lines, autolim=False)
    ax.scatter(
        xy[~clutter, 0],
        xy[~clutter, 1],
        c=distance[~clutter],
        cmap=cmap,
        norm=norm,
        s=1.5,
        linewidths=0,
        zorder=2,
        rasterized=True,
    )
    ax.scatter(
        xy[clutter, 0], xy[clutter, 1], c=_CLUTTER, s=1.5, linewidths=0, zorder=2, rasterized=True
    )
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    style_axes(ax)
