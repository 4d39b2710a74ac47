"""The evaluation report: self-contained HTML (Jinja2) and the same report as PDF (Typst).

Every number and sentence is computed and formatted once, in a view model
(:class:`ReportView`, :mod:`~exporters.report.view`); two thin templates show it:
``templates/report.html.j2`` (with ``templates/_partials/``) as HTML and
``templates/report.typ`` as an A4 PDF typeset by Typst (:mod:`~exporters.report.typeset`;
a wheel with its own compiler: no system library). The figures are drawn once by matplotlib
and embedded as SVG in both: the PDF's are vectors. A test holds the two renderings to the
same text (``tests/exporters/test_report_pdf_text.py``).

HTML templates of one's own (``templates_dir`` without ``report.typ``) get their PDF laid
out from the HTML by WeasyPrint (the optional ``loceval[html-pdf]``, with pango), with the
figures as PNG. :mod:`~exporters.report.render` renders both, and holds the Jinja2 render
and the PDF engines the summary and control-point reports share.
"""

from __future__ import annotations

from exporters.report.figures import ReportPlots, render_report_plots
from exporters.report.render import (
    DEFAULT_TEMPLATES_DIR,
    PDF_TEMPLATE_NAME,
    TEMPLATE_NAME,
    check_pdf,
    check_templates,
    html_to_pdf,
    layout_pdf,
    pdf_available,
    pdf_engine,
    pdf_figure_format,
    render_report,
    render_report_html,
    render_report_pdf,
    render_template,
    render_view_html,
    render_view_pdf,
    report_figure_formats,
)
from exporters.report.typeset import typeset_pdf
from exporters.report.view import BEST_MARK, ReportView, build_report_view

__all__ = [
    "BEST_MARK",
    "DEFAULT_TEMPLATES_DIR",
    "PDF_TEMPLATE_NAME",
    "TEMPLATE_NAME",
    "ReportPlots",
    "ReportView",
    "build_report_view",
    "check_pdf",
    "check_templates",
    "html_to_pdf",
    "layout_pdf",
    "pdf_available",
    "pdf_engine",
    "pdf_figure_format",
    "render_report",
    "render_report_html",
    "render_report_pdf",
    "render_report_plots",
    "render_template",
    "render_view_html",
    "render_view_pdf",
    "report_figure_formats",
    "typeset_pdf",
]
