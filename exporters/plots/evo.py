"""The plot files of ``loceval ape/rpe --save_plot PATH``: evo's two figures, at evo's names.

evo's ``--save_plot plot.pdf`` writes one PDF of two pages; ``--save_plot plot.png`` (or
another image format) writes ``plot_raw.png`` and ``plot_map.png``; a path without a
suffix is written as PNG (observed with evo 1.38.1, issue 44). loceval draws the same
two figures on its own: *raw*, the error of each pose (or pair) over time with its RMSE,
mean and median and the band of one standard deviation about the mean; *map*, the paths
from above, the reference dashed and the estimate coloured by its error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

import numpy as np
from matplotlib.figure import Figure

from exporters.plots.figure import REFERENCE_COLOUR, WIDTH_IN, estimate_colour
from loceval.errors import InputError
from loceval.metrics.pose_errors import ErrorSeries
from loceval.trajectory import Trajectory

__all__ = ["IMAGE_SUFFIXES", "write_error_plots"]

IMAGE_SUFFIXES: Final = (".pdf", ".png", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff")
"""The suffixes ``--save_plot`` takes (matplotlib's formats); none means PNG, as evo."""

_NS_PER_S: Final = 1e9
_HEIGHT_IN: Final = 4.0


def write_error_plots(
    path: Path,
    *,
    title: str,
    label: str,
    series: ErrorSeries,
    at_pose: np.ndarray,
    reference: Trajectory,
    estimate: Trajectory,
) -> tuple[Path, ...]:
    """Write the *raw* and *map* figures where evo's ``--save_plot PATH`` writes them.

    Args:
        path: ``--save_plot``'s path; its suffix chooses the format.
        title: the statistics' title (``APE w.r.t. translation part (m)``).
        label: the error axis' label (``APE (m)``).
        series: the errors and their stamps.
        at_pose: the index into the matched poses of each error (RPE: the pair's second).
        reference: the matched reference poses.
        estimate: the matched estimate poses after the alignment.

    Returns:
        The files written.

    Raises:
        InputError: a suffix that is no image format.
    """
    suffix = path.suffix.lower()
    if suffix and suffix not in IMAGE_SUFFIXES:
        msg = (
            f"The plot {path.name}: {suffix} is no plot format; use one of "
            f"{', '.join(IMAGE_SUFFIXES)} (or no suffix for PNG)."
        )
        raise InputError(msg)
    raw = _raw(title, label, series)
    drawn = _map(label, series, at_pose, reference, estimate)
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".pdf":
        from matplotlib.backends.backend_pdf import PdfPages  # noqa: PLC0415

        with PdfPages(path) as pdf:
            pdf.savefig(raw)
            pdf.savefig(drawn)
        return (path,)
    ext = suffix or ".png"
    files = (path.with_name(f"{path.stem}_raw{ext}"), path.with_name(f"{path.stem}_map{ext}"))
    for figure, target in zip((raw, drawn), files, strict=True):
        figure.savefig(target, format=ext.lstrip("."))
    return files


def _raw(title: str, label: str, series: ErrorSeries) -> Figure:
    """The errors over time with their RMSE, mean, median and the mean's 1-sigma band."""
    fig = Figure(figsize=(WIDTH_IN, _HEIGHT_IN), layout="constrained")
    ax = fig.add_subplot()
    values = series.values
    t = (series.stamps_ns - series.stamps_ns[0]) / _NS_PER_S if len(series) else values
    ax.plot(t, values, color="0.35", linewidth=0.8, label=label)
    stats = series.stats
    ax.axhspan(stats.mean - stats.std, stats.mean + stats.std, color="0.85", label="std")
    for name, value, colour in (
        ("rmse", stats.rmse, "tab:blue"),
        ("median", stats.median, "tab:orange"),
        ("mean", stats.mean, "tab:green"),
    ):
        ax.axhline(value, color=colour, linewidth=1.0, label=name)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(label)
    ax.set_title(title.replace("\n", " "), fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    return fig


def _map(
    label: str,
    series: ErrorSeries,
    at_pose: np.ndarray,
    reference: Trajectory,
    estimate: Trajectory,
) -> Figure:
    """The paths from above: the reference dashed, the estimate coloured by the error."""
    fig = Figure(figsize=(WIDTH_IN, WIDTH_IN * 0.8), layout="constrained")
    ax = fig.add_subplot()
    ref = reference.positions_xyz
    ax.plot(ref[:, 0], ref[:, 1], "--", color=REFERENCE_COLOUR, linewidth=1.0, label="reference")
    est = estimate.positions_xyz
    ax.plot(est[:, 0], est[:, 1], color=estimate_colour(0), linewidth=0.5, alpha=0.4)
    points = est[np.asarray(at_pose, dtype=np.int64)]
    dots = ax.scatter(points[:, 0], points[:, 1], c=series.values, s=4, cmap="jet")
    fig.colorbar(dots, ax=ax, label=label)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=7, loc="upper right")
    return fig
