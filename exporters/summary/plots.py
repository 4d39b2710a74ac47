"""The summary report's figures: errors over the runs, and the reference paths from above.

Drawn like the evaluation report's plots (:mod:`exporters.plots`): a figure built directly,
no pyplot, rendered to SVG for the HTML and the PDF (PNG for a PDF WeasyPrint lays out).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from typing import Final

import numpy as np
from matplotlib.axes import Axes
from matplotlib.dates import AutoDateLocator, ConciseDateFormatter, date2num

from exporters.plots.figure import (
    TOLERANCE_COLOUR,
    ImageFormat,
    Plot,
    decimate_uniform,
    encode_plot,
    estimate_colour,
)
from exporters.plots.mpl import legend_above, new_figure, style_axes
from exporters.summary.model import (
    UTC,
    SummaryInput,
    SummaryRun,
    date_text,
    runs_with_path,
    sorted_runs,
    system_names,
)

__all__ = [
    "PATH_LEGEND_MAX",
    "PATH_PLOT_POINTS",
    "plot_paths",
    "plot_trend",
    "render_summary_plots",
]

PATH_PLOT_POINTS: Final = 2000
"""Most vertices drawn per reference path in the paths-from-above figure (drawing only)."""
PATH_LEGEND_MAX: Final = 8
"""Up to this many runs are named in that figure's legend; more share one entry."""


def _date_axis(ax: Axes, times: Sequence[dt.datetime]) -> None:
    """Dates along x (UTC), padded so one run or runs at one time still get an axis."""
    lo, hi = min(times), max(times)
    pad = max((hi - lo) * 0.04, dt.timedelta(hours=12))
    left, right = date2num([lo - pad, hi + pad])  # type: ignore[no-untyped-call]
    ax.set_xlim(float(left), float(right))
    locator = AutoDateLocator(tz=UTC, minticks=3, maxticks=8)  # type: ignore[no-untyped-call]
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(ConciseDateFormatter(locator, tz=UTC))  # type: ignore[no-untyped-call]


def plot_trend(
    summary: SummaryInput,
    *,
    formats: Sequence[ImageFormat] = ("svg",),
    tolerance_m: float | None = None,
) -> Plot | None:
    """ATE RMSE and RPE RMSE of each system against the run date; None without figures.

    Args:
        summary: the runs.
        formats: the encodings to produce.
        tolerance_m: the tolerance distance drawn dashed on the ATE row, if any.

    Returns:
        The figure, or None when no succeeded run has a figure to draw.
    """
    runs = sorted_runs(summary.runs)
    names = system_names(runs)
    done = [r for r in runs if r.status == "succeeded"]
    rows = (("ATE RMSE [m]", "ate_rmse_m"), ("RPE RMSE [m]", "rpe_rmse_m"))
    if not any(
        getattr(r.systems[name], attr) is not None
        for r in done
        for name in names
        if name in r.systems
        for _, attr in rows
    ):
        return None
    many = len(runs) > 20
    fig = new_figure(1.3 + 1.75 * len(rows))
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    failed_at = [r.recorded_at for r in runs if r.status == "failed"]
    tops = dict.fromkeys((attr for _, attr in rows), 0.0)
    for ax, (label, attr) in zip(axes, rows, strict=True):
        for k, name in enumerate(names):
            points = [
                (r.recorded_at, value)
                for r in done
                if name in r.systems and (value := getattr(r.systems[name], attr)) is not None
            ]
            if not points:
                continue
            tops[attr] = max(tops[attr], *(v for _, v in points))
            ax.plot(
                [t for t, _ in points],
                [v for _, v in points],
                color=estimate_colour(k),
                linewidth=1.0 if many else 1.3,
                marker="o",
                markersize=3.0 if many else 5.0,
                label=name,
            )
        if attr == "ate_rmse_m" and tolerance_m is not None:
            ax.axhline(
                tolerance_m,
                color=TOLERANCE_COLOUR,
                linestyle="--",
                linewidth=1.0,
                label=f"tolerance {tolerance_m:g} m",
            )
        if failed_at:
            ax.plot(
                failed_at,
                [0.0] * len(failed_at),
                linestyle="none",
                marker="x",
                markersize=6,
                color="#616161",
                clip_on=False,
                zorder=5,
                label="failed run",
            )
        ax.set_ylabel(label)
        # Head room over the highest point and the tolerance line, so neither sits on the edge.
        top = max(tops[attr], tolerance_m or 0.0 if attr == "ate_rmse_m" else 0.0, 0.01 / 1.15)
        ax.set_ylim(0.0, 1.15 * top)
        style_axes(ax)
    _date_axis(axes[-1], [r.recorded_at for r in runs])
    axes[-1].set_xlabel("recorded (UTC)")
    legend_above(fig, axes[0])
    caption = (
        "Each system's RMSE per run against the run's recording date: the absolute error "
        "after alignment (top) and the error of the motion per step (bottom)."
    )
    if tolerance_m is not None:
        caption += (
            f" The dashed line is the tolerance distance ({tolerance_m:g} m); the verdict "
            "asks a share of poses within it, so an RMSE below the line is not by itself "
            "a pass."
        )
    if failed_at:
        caption += " Grey crosses on the time axis are runs that failed."
    if len(runs) == 1:
        caption += " With one run each system is a single point."
    return encode_plot(fig, formats, key="trend", title="Errors over the runs", caption=caption)


def plot_paths(
    runs: Sequence[SummaryRun], *, formats: Sequence[ImageFormat] = ("svg",)
) -> Plot | None:
    """The reference paths from above (x-y): the baseline in black, later runs over it.

    Args:
        runs: the runs; those with ``reference_xyz`` are drawn.
        formats: the encodings to produce.

    Returns:
        The figure, or None with fewer than two paths.
    """
    with_path = runs_with_path(runs)
    if len(with_path) < 2:
        return None
    paths = [(run, xyz[decimate_uniform(len(xyz), PATH_PLOT_POINTS)]) for run, xyz in with_path]
    every = np.concatenate([xy[:, :2] for _, xy in paths])
    span = np.ptp(every, axis=0)
    ratio = 1.0 if span[0] <= 0 else float(span[1] / span[0])
    fig = new_figure(float(np.clip(6.2 * ratio, 2.6, 7.0)) + 1.2)
    ax = fig.add_subplot()
    named = len(paths) <= PATH_LEGEND_MAX
    later_colour = "#3b4cc0"
    for k, (row, xyz) in enumerate(paths[1:], start=1):
        label = (
            f"{date_text(row.recorded_at)} {row.dataset}"
            if named
            else (f"later runs ({len(paths) - 1})" if k == 1 else None)
        )
        ax.plot(
            xyz[:, 0],
            xyz[:, 1],
            color=estimate_colour(k + 2) if named else later_colour,
            linewidth=0.9,
            alpha=0.8 if named else 0.35,
            label=label,
        )
    base_row, base = paths[0]
    ax.plot(
        base[:, 0],
        base[:, 1],
        color="black",
        linewidth=1.8,
        zorder=4,
        label=f"baseline: {date_text(base_row.recorded_at)} {base_row.dataset}",
    )
    ax.plot(
        [base[0, 0]],
        [base[0, 1]],
        marker="o",
        markersize=7,
        markerfacecolor="white",
        markeredgecolor="black",
        linestyle="none",
        zorder=5,
        label="start of the baseline",
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    style_axes(ax)
    legend_above(fig, ax)
    return encode_plot(
        fig,
        formats,
        key="paths_xy",
        title="Reference paths from above (x-y)",
        caption=(
            "The reference (ground-truth) path of every run with one, in the reference "
            "system's frame: the first run (the baseline) in black, the later runs over it."
        ),
    )


def render_summary_plots(
    summary: SummaryInput, *, formats: Sequence[ImageFormat] = ("svg",)
) -> tuple[Plot, ...]:
    """Render the summary's figures: the trend and, with two paths or more, the paths.

    Args:
        summary: the runs.
        formats: the encodings to produce from each figure.

    Returns:
        The figures in report order (none for an empty selection).
    """
    plots = [
        plot_trend(
            summary,
            formats=formats,
            tolerance_m=None if summary.tolerance is None else summary.tolerance.distance_m,
        ),
        plot_paths(summary.runs, formats=formats),
    ]
    return tuple(p for p in plots if p is not None)
