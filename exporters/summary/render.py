"""Rendering the summary report: its view model through ``templates/summary.html.j2``.

HTML with SVG plots, and an A4 PDF (PNG plots, WeasyPrint), with the evaluation report's
Jinja2 render and template check (:mod:`exporters.report`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

from exporters.report import DEFAULT_TEMPLATES_DIR, check_templates, html_to_pdf, render_template
from exporters.summary.model import SummaryInput, repeatability
from exporters.summary.plots import render_summary_plots
from exporters.summary.view import SummaryView, build_summary_view

__all__ = [
    "SUMMARY_TEMPLATE_NAME",
    "render_summary",
    "render_summary_html",
    "render_summary_pdf",
    "render_summary_view_html",
]

SUMMARY_TEMPLATE_NAME: Final = "summary.html.j2"


def _templates(templates_dir: Path | None) -> Path:
    return check_templates(
        templates_dir or DEFAULT_TEMPLATES_DIR, SUMMARY_TEMPLATE_NAME, label="summary"
    )


def render_summary_view_html(view: SummaryView, *, templates_dir: Path) -> bytes:
    """Render a summary view model to HTML (UTF-8).

    Raises:
        ExportUnavailableError: Jinja2 is not installed.
        ExportError: the templates are missing or broken.
    """
    return render_template(
        _templates(templates_dir),
        SUMMARY_TEMPLATE_NAME,
        label="summary",
        requirement="The summary report",
        summary=view,
    )


def render_summary_html(summary: SummaryInput, *, templates_dir: Path) -> bytes:
    """Render the summary as one self-contained HTML file (SVG plots).

    Raises:
        ExportUnavailableError: Jinja2 or matplotlib is missing.
        ExportError: the templates are missing or broken.
    """
    folder = _templates(templates_dir)
    return render_summary_view_html(build_summary_view(summary), templates_dir=folder)


def render_summary_pdf(summary: SummaryInput, *, templates_dir: Path) -> bytes:
    """Render the summary as an A4 PDF (PNG plots, WeasyPrint).

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or WeasyPrint is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates(templates_dir)
    view = build_summary_view(summary, image_format="png")
    return html_to_pdf(render_summary_view_html(view, templates_dir=folder))


def render_summary(summary: SummaryInput, *, templates_dir: Path) -> tuple[bytes, bytes]:
    """Render the summary as HTML and PDF, drawing each plot once for both formats.

    Args:
        summary: the runs and what they are.
        templates_dir: the template folder (the repository's ``templates/``).

    Returns:
        ``(html, pdf)`` as bytes.

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or WeasyPrint is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates(templates_dir)
    plots = render_summary_plots(summary, formats=("svg", "png"))
    rows = repeatability(summary.runs)
    html = render_summary_view_html(
        build_summary_view(summary, image_format="svg", plots=plots, repeatability_rows=rows),
        templates_dir=folder,
    )
    printable = render_summary_view_html(
        build_summary_view(summary, image_format="png", plots=plots, repeatability_rows=rows),
        templates_dir=folder,
    )
    return html, html_to_pdf(printable)
