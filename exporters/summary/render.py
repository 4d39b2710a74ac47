"""Rendering the summary report: its view model through ``summary.html.j2`` and ``summary.typ``.

HTML with SVG plots, and an A4 PDF typeset by Typst from the same view model (the plots as
vectors), with the evaluation report's Jinja2 render, template check and PDF engines
(:mod:`exporters.report`): a folder of HTML templates only has WeasyPrint lay its HTML out
(PNG plots).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

from exporters.errors import ExportOptionsError
from exporters.report import (
    DEFAULT_TEMPLATES_DIR,
    check_pdf,
    check_templates,
    layout_pdf,
    pdf_figure_format,
    render_template,
)
from exporters.summary.model import SummaryInput, repeatability
from exporters.summary.plots import render_summary_plots
from exporters.summary.view import SummaryView, build_summary_view

if TYPE_CHECKING:
    from collections.abc import Collection
    from pathlib import Path

__all__ = [
    "SUMMARY_FORMATS",
    "SUMMARY_PDF_TEMPLATE_NAME",
    "SUMMARY_TEMPLATE_NAME",
    "render_summary",
    "render_summary_files",
    "render_summary_html",
    "render_summary_pdf",
    "render_summary_view_html",
    "render_summary_view_pdf",
    "summary_formats",
]

SUMMARY_TEMPLATE_NAME: Final = "summary.html.j2"
SUMMARY_PDF_TEMPLATE_NAME: Final = "summary.typ"

SUMMARY_FORMATS: Final = ("summary.html", "summary.pdf")
"""The files a summary report can be written as, in the order they are written."""


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


def render_summary_view_pdf(view: SummaryView, *, templates_dir: Path) -> bytes:
    """Lay a summary view model out as an A4 PDF (Typst, or WeasyPrint for HTML-only folders).

    Raises:
        ExportUnavailableError: the PDF's engine is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates(templates_dir)
    return layout_pdf(
        folder,
        SUMMARY_PDF_TEMPLATE_NAME,
        view,
        label="summary",
        html=lambda: render_summary_view_html(view, templates_dir=folder),
    )


def render_summary_pdf(summary: SummaryInput, *, templates_dir: Path) -> bytes:
    """Render the summary as an A4 PDF (Typst; plots as vectors).

    Raises:
        ExportUnavailableError: matplotlib or the PDF's engine is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates(templates_dir)
    check_pdf(folder, SUMMARY_PDF_TEMPLATE_NAME)
    image_format = pdf_figure_format(folder, SUMMARY_PDF_TEMPLATE_NAME)
    view = build_summary_view(summary, image_format=image_format)
    return render_summary_view_pdf(view, templates_dir=folder)


def render_summary(summary: SummaryInput, *, templates_dir: Path) -> tuple[bytes, bytes]:
    """Render the summary as HTML and PDF, drawing each plot once for both formats.

    Args:
        summary: the runs and what they are.
        templates_dir: the template folder (the repository's ``templates/``).

    Returns:
        ``(html, pdf)`` as bytes.

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or the PDF's engine is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates(templates_dir)
    check_pdf(folder, SUMMARY_PDF_TEMPLATE_NAME)
    printed = pdf_figure_format(folder, SUMMARY_PDF_TEMPLATE_NAME)
    plots = render_summary_plots(summary, formats=tuple(dict.fromkeys(("svg", printed))))
    rows = repeatability(summary.runs)
    view = build_summary_view(summary, image_format="svg", plots=plots, repeatability_rows=rows)
    html = render_summary_view_html(view, templates_dir=folder)
    if printed != "svg":  # WeasyPrint lays out the folder's HTML, with PNG figures
        view = build_summary_view(
            summary, image_format=printed, plots=plots, repeatability_rows=rows
        )
    return html, render_summary_view_pdf(view, templates_dir=folder)


def summary_formats(names: Collection[str] | None) -> tuple[str, ...]:
    """Return the summary files that ``names`` ask for, in :data:`SUMMARY_FORMATS` order.

    ``None`` asks for every format. A name is a file name or its suffix (``summary.pdf``,
    ``pdf``, ``.PDF``); case and surrounding spaces do not matter.

    Raises:
        ExportOptionsError: a name that is no summary format, or no name at all.
    """
    if names is None:
        return SUMMARY_FORMATS
    by_name = {f: f for f in SUMMARY_FORMATS} | {f.rpartition(".")[2]: f for f in SUMMARY_FORMATS}
    wanted: set[str] = set()
    for text in names:
        key = text.strip().lower()
        found = by_name.get(key) or by_name.get(key.removeprefix("."))
        if found is None:
            msg = f"No summary format named {text!r}; choose from {', '.join(SUMMARY_FORMATS)}."
            raise ExportOptionsError(msg, option="formats")
        wanted.add(found)
    if not wanted:
        msg = f"Name at least one summary format: {', '.join(SUMMARY_FORMATS)}."
        raise ExportOptionsError(msg, option="formats")
    return tuple(f for f in SUMMARY_FORMATS if f in wanted)


def render_summary_files(
    summary: SummaryInput, formats: Collection[str] | None, *, templates_dir: Path
) -> dict[str, bytes]:
    """Render the summary as the files ``formats`` ask for (all when None), and no other.

    An HTML-only summary never lays out a PDF; both formats draw each plot once
    (:func:`render_summary`).

    Args:
        summary: the runs and what they are.
        formats: file names as :func:`summary_formats` takes them.
        templates_dir: the template folder (the repository's ``templates/``).

    Returns:
        File name (``summary.html``, ``summary.pdf``) to content, in :data:`SUMMARY_FORMATS`
        order.

    Raises:
        ExportOptionsError: a format that is no summary format.
        ExportUnavailableError: Jinja2, matplotlib or (for the PDF) its engine is missing.
        ExportError: the templates are missing or the layout failed.
    """
    wanted = summary_formats(formats)
    if wanted == SUMMARY_FORMATS:
        html, pdf = render_summary(summary, templates_dir=templates_dir)
        return {"summary.html": html, "summary.pdf": pdf}
    if wanted == ("summary.html",):
        return {"summary.html": render_summary_html(summary, templates_dir=templates_dir)}
    return {"summary.pdf": render_summary_pdf(summary, templates_dir=templates_dir)}
