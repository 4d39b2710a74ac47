"""The report's figures, drawn once per run and encoded for each report that embeds them.

The HTML report and its PDF (Typst) embed every figure as SVG: a run writing both draws and
encodes each figure once. A PDF WeasyPrint lays out of HTML templates of one's own embeds
PNG: then each figure is drawn once and encoded twice (:func:`render_report_plots` with both
formats).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from exporters.options import ExportOptions
from exporters.plots import DEFAULT_MAX_POINTS, ImageFormat, Plot, render_plots
from exporters.plots.clock import plot_clock_correlation, plot_clock_drift
from exporters.plots.underlay import floor_plan_segments
from loceval.evaluation import EvaluationResult

__all__ = ["ReportPlots", "render_report_plots"]


@dataclass(frozen=True, slots=True)
class ReportPlots:
    """Every figure of the report, drawn once and encoded in each format a report embeds.

    Both reports embed the SVG (a WeasyPrint PDF the PNG) of the same figures, so a run
    that writes both draws each figure once (:func:`render_report_plots`).

    Attributes:
        figures: the numbered figures, in report order (:func:`exporters.plots.render_plots`).
        clock: the figure of the "Clocks and device offset" section, or None (no clock
            offset estimated).
        clock_drift: the section's figure of the offset along the run, or None (no clock's
            drift checked).
    """

    figures: tuple[Plot, ...]
    clock: Plot | None
    clock_drift: Plot | None = None


def render_report_plots(
    result: EvaluationResult,
    options: ExportOptions,
    *,
    formats: Sequence[ImageFormat] = ("svg",),
    max_points: int = DEFAULT_MAX_POINTS,
) -> ReportPlots:
    """Draw every figure of the report once and encode it in ``formats``.

    Args:
        result: the evaluation.
        options: the export options (the building's floor plan under the plan views).
        formats: the encodings to produce: ``svg`` (HTML and Typst's PDF), ``png`` (a
            WeasyPrint PDF) or both.
        max_points: most vertices drawn per plotted line (drawing only).

    Returns:
        The figures and the clock section's figure.
    """
    return ReportPlots(
        figures=render_plots(
            result,
            max_points=max_points,
            formats=formats,
            floor_plan=floor_plan_segments(result.reference.positions_xyz[:, 2], options),
        ),
        clock=plot_clock_correlation(result, max_points=max_points, formats=formats),
        clock_drift=plot_clock_drift(result, formats=formats),
    )
