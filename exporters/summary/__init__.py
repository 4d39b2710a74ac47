"""The summary report of a scheduled report: many runs (recordings) of one site, one file.

Every week a site lead gets one report over the recordings a schedule selected: each run is
one evaluation (a reference and one or more estimated systems). The service builds a
:class:`SummaryInput`; this package computes everything the report shows (per-run table,
per-system statistics, the trend over time and the repeatability of the reference path)
into a view model (:class:`SummaryView`) and renders it with the evaluation report's look
(``templates/summary.html.j2``, ``templates/report.css``) as self-contained HTML (SVG
plots) and as an A4 PDF typeset by Typst from the same view (``templates/summary.typ``,
the plots as vectors).

Split by concern as the evaluation report is: :mod:`~exporters.summary.model` (the input,
statistics and repeatability rows), :mod:`~exporters.summary.view` (the formatted view
model), :mod:`~exporters.summary.plots` (the figures) and :mod:`~exporters.summary.render`
(HTML and PDF). The distances behind the repeatability are the core's
(:mod:`loceval.metrics.repeatability`, :mod:`loceval.core.polyline`).

Repeatability follows the reference-robot paper's re-drive test: a path recorded once is
driven again, and the re-driven path is compared with the first in space (the paper
reports a median distance of 10.1 cm and a maximum of 24.6 cm for its robot), together
with the timing, because a system's results change with the speed it is carried at.
Comparing one system over many runs in one building is the framework paper's use (one
algorithm in different environments and runs, §2).
"""

from __future__ import annotations

from exporters.summary.model import (
    RepeatabilityRow,
    SummaryInput,
    SummaryRun,
    SystemFigures,
    SystemStats,
    best_systems,
    repeatability,
    system_stats,
)
from exporters.summary.plots import plot_paths, plot_trend, render_summary_plots
from exporters.summary.render import (
    SUMMARY_FORMATS,
    SUMMARY_TEMPLATE_NAME,
    render_summary,
    render_summary_files,
    render_summary_html,
    render_summary_pdf,
    render_summary_view_html,
    render_summary_view_pdf,
    summary_formats,
)
from exporters.summary.view import SummaryFigure, SummaryView, build_summary_view

__all__ = [
    "SUMMARY_FORMATS",
    "SUMMARY_TEMPLATE_NAME",
    "RepeatabilityRow",
    "SummaryFigure",
    "SummaryInput",
    "SummaryRun",
    "SummaryView",
    "SystemFigures",
    "SystemStats",
    "best_systems",
    "build_summary_view",
    "plot_paths",
    "plot_trend",
    "render_summary",
    "render_summary_files",
    "render_summary_html",
    "render_summary_pdf",
    "render_summary_plots",
    "render_summary_view_html",
    "render_summary_view_pdf",
    "repeatability",
    "summary_formats",
    "system_stats",
]
