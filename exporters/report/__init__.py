"""The evaluation report: self-contained HTML (Jinja2) and the same report as PDF (WeasyPrint).

One set of templates (``templates/report.html.j2`` with ``templates/_partials/``) renders
both: the HTML carries a screen and a print stylesheet, and WeasyPrint lays the same HTML
out on A4 pages. Plots are embedded as ``data:`` URIs, so the report is one file that needs
no network and no other file: SVG in the HTML, 200 dpi PNG in the PDF (WeasyPrint draws
matplotlib's SVG slowly; the picture is the same).

The templates hold loops, conditions and filters only; every number is computed and
formatted in a view model (:class:`ReportView`, :mod:`~exporters.report.view`), so tests can
compare the report against the result's statistics; :mod:`~exporters.report.render` renders
it (and holds the Jinja2 render and the PDF layout the summary report shares).
"""

from __future__ import annotations

from exporters.report.figures import ReportPlots, render_report_plots
from exporters.report.render import (
    DEFAULT_TEMPLATES_DIR,
    TEMPLATE_NAME,
    check_pdf,
    check_templates,
    html_to_pdf,
    pdf_available,
    render_report,
    render_report_html,
    render_report_pdf,
    render_template,
    render_view_html,
)
from exporters.report.view import BEST_MARK, ReportView, build_report_view

__all__ = [
    "BEST_MARK",
    "DEFAULT_TEMPLATES_DIR",
    "TEMPLATE_NAME",
    "ReportPlots",
    "ReportView",
    "build_report_view",
    "check_pdf",
    "check_templates",
    "html_to_pdf",
    "pdf_available",
    "render_report",
    "render_report_html",
    "render_report_pdf",
    "render_report_plots",
    "render_template",
    "render_view_html",
]
