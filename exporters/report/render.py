"""Rendering the evaluation report: Jinja2 to HTML, Typst to an A4 PDF.

The PDF is typeset by Typst from ``report.typ`` beside the HTML template, reading the same
view model (:mod:`exporters.report.typeset`): no system library. A templates folder of
one's own that has no ``.typ`` template (HTML templates only) gets its PDF laid out from its
HTML by WeasyPrint instead, which is an optional extra (``loceval[html-pdf]``, with the
system libraries pango) and is used for nothing else.

:func:`render_template`, :func:`check_templates`, :func:`pdf_engine` and :func:`html_to_pdf`
are shared with the summary and control-point reports.
"""

from __future__ import annotations

import base64
import contextlib
import functools
import logging
import re
import threading
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Final, Literal, TypeAlias

from exporters.errors import ExportError, ExportUnavailableError
from exporters.options import ExportOptions
from exporters.plots import DEFAULT_MAX_POINTS, ImageFormat
from exporters.report import pdf_png
from exporters.report.figures import ReportPlots, render_report_plots
from exporters.report.typeset import check_typst, typeset_pdf
from exporters.report.view import ReportView, build_report_view
from exporters.viewer import ViewerFragment, viewer_fragment
from loceval.core.display import shown_text
from loceval.evaluation import EvaluationResult

if TYPE_CHECKING:
    import jinja2

__all__ = [
    "DEFAULT_TEMPLATES_DIR",
    "PDF_TEMPLATE_NAME",
    "TEMPLATE_NAME",
    "PdfEngine",
    "check_pdf",
    "check_templates",
    "html_to_pdf",
    "layout_pdf",
    "pdf_available",
    "pdf_engine",
    "pdf_figure_format",
    "preload_templates",
    "render_report",
    "render_report_html",
    "render_report_pdf",
    "render_template",
    "render_view_html",
    "render_view_pdf",
    "report_figure_formats",
]

logger = logging.getLogger(__name__)

DEFAULT_TEMPLATES_DIR: Final[Path] = Path(__file__).resolve().parents[2] / "templates"
"""The repository's ``templates/`` folder, used when the options name none."""
TEMPLATE_NAME: Final = "report.html.j2"
PDF_TEMPLATE_NAME: Final = "report.typ"

PdfEngine: TypeAlias = Literal["typst", "weasyprint"]
"""What lays out a PDF: Typst from a ``.typ`` template, or WeasyPrint from the HTML."""


def pdf_engine(templates_dir: Path, typst_template: str = PDF_TEMPLATE_NAME) -> PdfEngine:
    """Return what lays out the PDFs of a templates folder.

    Typst when the folder has the ``.typ`` template (the repository's does); a folder of
    one's own with HTML templates only is laid out from its HTML by WeasyPrint.
    """
    return "typst" if (templates_dir / typst_template).is_file() else "weasyprint"


def pdf_figure_format(templates_dir: Path, typst_template: str = PDF_TEMPLATE_NAME) -> ImageFormat:
    """Return how a PDF of the folder embeds figures: SVG (Typst, vectors) or PNG (WeasyPrint)."""
    return "svg" if pdf_engine(templates_dir, typst_template) == "typst" else "png"


_SEPARATOR: Final = re.compile(r"(?<=[^\W_])([_/@:.])(?=[^\W_])")
"""A separator joining two parts of a name (``fr2_desk``, ``map:base_link``, ``data/public``)."""


_BREAKABLE_FROM: Final = 12
"""Words of up to this many characters never break (numbers such as ``0.1`` included)."""


def breakable(value: object) -> object:
    """Jinja filter: a name that may break after its separators and nowhere else.

    Escapes the text and puts ``<wbr>`` after each ``_ / @ : .`` that joins two letters or
    digits inside a word longer than twelve characters, so ``fr2_desk_groundtruth`` or
    ``tf:map:base_link`` wraps at a part boundary in a narrow column (the stylesheet
    forbids breaks inside a word). Text that is not a string (numbers, None) and markup
    pass unchanged.
    """
    if not isinstance(value, str) or hasattr(value, "__html__"):
        return value
    from markupsafe import Markup, escape  # noqa: PLC0415  (comes with jinja2: loceval[report])

    def word(text: str) -> Markup:
        if len(text) <= _BREAKABLE_FROM:
            return escape(text)
        parts = _SEPARATOR.split(text)  # the separators at odd positions
        # Every part is escaped before it joins the markup; <wbr> is the only tag added.
        wbr = Markup("<wbr>")
        return Markup("").join(escape(p) + wbr if k % 2 else escape(p) for k, p in enumerate(parts))

    # Whitespace (kept as it is) still breaks lines; short words never need to.
    pieces = re.split(r"(\s+)", str(shown_text(value)))
    return Markup("").join(word(p) for p in pieces)


def check_templates(folder: Path, name: str, *, label: str) -> Path:
    """Return ``folder`` if it holds the template ``name``.

    Raises:
        ExportError: the template is missing (the message names the ``label`` template).
    """
    if not (folder / name).is_file():
        msg = (
            f"No {label} template {name!r} in {str(folder)!r}; point templates_dir "
            "at the repository's templates/ folder."
        )
        raise ExportError(msg)
    return folder


def render_template(
    templates_dir: Path, name: str, *, label: str, requirement: str, **context: object
) -> bytes:
    """Render a report template (autoescaped, strict about undefined names) to UTF-8.

    Args:
        templates_dir: the template folder.
        name: the template's file name.
        label: names the template in messages (``report``, ``summary``).
        requirement: what needs Jinja2, for the message when it is missing.
        context: the template's variables.

    Raises:
        ExportUnavailableError: Jinja2 is not installed.
        ExportError: the template is broken.
    """
    try:
        import jinja2  # noqa: PLC0415  (optional dependency: loceval[report])
    except ImportError as err:
        msg = f"{requirement} needs jinja2; install loceval[report]."
        raise ExportUnavailableError(msg) from err
    env = _environment(templates_dir)
    try:
        html = env.get_template(name).render(**context)
    except jinja2.TemplateError as err:
        msg = f"The {label} template in {str(templates_dir)!r} failed: {err}."
        raise ExportError(msg) from err
    return html.encode("utf-8")


@functools.lru_cache(maxsize=8)
def _environment(templates_dir: Path) -> jinja2.Environment:
    """Return the Jinja2 environment of a template folder, made once per process.

    The environment keeps its compiled templates, so the report, its PDF and the next
    report render without compiling the templates again (0.13 s each on the test machine).
    It checks each template's modification time when it is used, so an edited template is
    still picked up. Environments are safe to render from several threads. The compiled
    code is also kept on disk for the next process (:mod:`exporters.report.bytecode`).
    """
    import jinja2  # noqa: PLC0415  (optional dependency: loceval[report])

    from exporters.report.bytecode import bytecode_cache  # noqa: PLC0415  (imports Jinja2)

    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(templates_dir),
        bytecode_cache=bytecode_cache(),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        finalize=shown_text,
    )
    env.filters["breakable"] = breakable
    return env


def preload_templates(templates_dir: Path = DEFAULT_TEMPLATES_DIR) -> None:
    """Compile the report templates of ``templates_dir`` ahead of the first report.

    The service's job processes start from a process that called this, so no job compiles
    them (:mod:`service.jobs.preload`). A template that fails is left to the report that
    uses it, which reports the failure.
    """
    import jinja2  # noqa: PLC0415  (optional dependency: loceval[report])

    env = _environment(templates_dir)
    for name in env.list_templates(filter_func=_is_report_template):
        with contextlib.suppress(jinja2.TemplateError):
            env.get_template(name)


def _is_report_template(name: str) -> bool:
    """A report or summary template: ``*.j2`` at the top or in ``_partials/``."""
    folder, _, file = name.rpartition("/")
    return file.endswith(".j2") and folder in {"", "_partials"}


def _templates_dir(options: ExportOptions, templates_dir: Path | None) -> Path:
    folder = templates_dir or options.templates_dir or DEFAULT_TEMPLATES_DIR
    return check_templates(folder, TEMPLATE_NAME, label="report")


def render_view_html(
    view: ReportView, *, templates_dir: Path, viewer: ViewerFragment | None = None
) -> bytes:
    """Render a view model to the report's HTML (UTF-8).

    Args:
        view: the report's view model.
        templates_dir: the template folder.
        viewer: the interactive viewer's section (HTML only; the PDF keeps its figures).

    Raises:
        ExportUnavailableError: Jinja2 is not installed.
        ExportError: the templates are missing or broken.
    """
    return render_template(
        templates_dir,
        TEMPLATE_NAME,
        label="report",
        requirement="report.html",
        report=view,
        viewer=viewer,
    )


_WEASYPRINT_LOCK: Final = threading.Lock()
_weasyprint_loaded: tuple[ModuleType, type[Exception]] | str | None = None


def _weasyprint() -> tuple[ModuleType, type[Exception]]:
    """Import WeasyPrint once per process: the module and its fatal URL-fetching error.

    The import is made once, under a lock, and its outcome kept: two report jobs on two
    worker threads importing it at the same time would otherwise see a half-initialised
    module (an AttributeError, reported as a bug), and a missing system library would be
    looked for again by every report.

    Raises:
        ExportUnavailableError: WeasyPrint or its system libraries (pango) are missing.
    """
    global _weasyprint_loaded  # noqa: PLW0603  (the process-wide outcome of one import)
    with _WEASYPRINT_LOCK:
        if _weasyprint_loaded is None:
            # before the import: WeasyPrint parses its own stylesheets as it is imported
            _quieten(logging.getLogger("weasyprint"), logging.getLogger("weasyprint.progress"))
            try:
                import weasyprint  # noqa: PLC0415  (optional dependency: loceval[html-pdf])
                from weasyprint import images  # noqa: PLC0415
                from weasyprint.urls import FatalURLFetchingError  # noqa: PLC0415

                pdf_png.install(images)  # the figures' PNG rows go into the PDF as they are
            except (ImportError, OSError) as err:  # OSError: pango/glib libraries missing
                first = (str(err).strip().splitlines() or [type(err).__name__])[0]
                _weasyprint_loaded = (
                    "The PDF of HTML templates of one's own (a templates folder without a "
                    ".typ template) is laid out by WeasyPrint, which needs its system "
                    "libraries (pango): install loceval[html-pdf] and the packages "
                    "libpango-1.0-0 and libpangoft2-1.0-0, or put the repository's .typ "
                    f"templates in the folder ({first[:200]})."
                )
            else:
                _weasyprint_loaded = (weasyprint, FatalURLFetchingError)
        loaded = _weasyprint_loaded
    if isinstance(loaded, str):
        raise ExportUnavailableError(loaded)
    return loaded


class _Quiet(logging.Filter):
    """Drops WeasyPrint's per-step progress lines and its notes on print-only CSS.

    WeasyPrint logs some twenty INFO lines per PDF (``weasyprint.progress``) and a warning
    for each ``print-color-adjust`` of the stylesheet (browsers need it to print colours;
    WeasyPrint always prints them): noise in the service's log, once per report.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        if record.name.endswith(".progress") and record.levelno < logging.WARNING:
            return False
        return "print-color-adjust" not in record.getMessage()


def _quieten(*loggers: logging.Logger) -> None:
    """Put the filter on WeasyPrint's loggers, once per process."""
    for each in loggers:
        if not any(isinstance(f, _Quiet) for f in each.filters):
            each.addFilter(_Quiet())


def check_pdf(
    templates_dir: Path = DEFAULT_TEMPLATES_DIR, typst_template: str = PDF_TEMPLATE_NAME
) -> None:
    """Check that PDFs of a templates folder can be made here, before any work for one.

    Raises:
        ExportUnavailableError: the folder's PDFs need WeasyPrint (no ``.typ`` template)
            and it or its system libraries (pango) are missing; or typst is missing.
    """
    if pdf_engine(templates_dir, typst_template) == "typst":
        check_typst()
    else:
        _weasyprint()


def pdf_available(
    templates_dir: Path = DEFAULT_TEMPLATES_DIR, typst_template: str = PDF_TEMPLATE_NAME
) -> bool:
    """Tell whether this process can write the PDFs of a templates folder.

    With the repository's templates (Typst) always, where loceval[report] is installed;
    with HTML templates of one's own, when WeasyPrint and pango load (the same
    once-per-process import as the PDF's, so the first call may take half a second).

    Returns:
        False when the PDF's engine is missing, True otherwise.
    """
    try:
        check_pdf(templates_dir, typst_template)
    except ExportUnavailableError:
        return False
    return True


def html_to_pdf(html: bytes) -> bytes:
    """Lay the report's HTML out on A4 pages with WeasyPrint.

    Only embedded images are fetched: the ``data:`` URLs of ``src`` attributes (which are
    handed to WeasyPrint as the bytes they hold, see :func:`_hoist_images`) and any other
    ``data:`` URL. Anything else (a network or file URL slipped into a template) stops the
    render, so a report never touches the network.

    Raises:
        ExportUnavailableError: WeasyPrint (or its system libraries) is not installed.
        ExportError: the layout failed or the HTML referred to a non-``data:`` resource.
    """
    weasyprint, fatal_fetch = _weasyprint()
    text, images = _hoist_images(html)
    try:
        document = weasyprint.HTML(string=text, url_fetcher=_embedded_fetcher(images))
        pdf = document.write_pdf()
    except fatal_fetch as err:
        msg = f"The report refers to a resource that is not embedded: {err}."
        raise ExportError(msg) from err
    return bytes(pdf)


_EMBEDDED_SRC: Final = re.compile(
    rb'(?<= src=")data:(image/[a-z0-9.+-]+);base64,([A-Za-z0-9+/]*={0,2})(?=")'
)
"""An image embedded in an ``src`` attribute as base64 (the report's figures)."""
_EMBEDDED_SCHEME: Final = "loceval-embedded"


def _hoist_images(html: bytes) -> tuple[str, dict[str, tuple[str, bytes]]]:
    """Take the base64 images out of the HTML; return it and the images by their new URL.

    The figures are most of a report's HTML (a 1.7 MB fr2_desk report is 1.6 MB of
    base64 PNG). WeasyPrint's HTML parser scans every character of it, and its selector
    matching lowercases each image's ``src`` once per attribute selector: 0.3 s of the
    PDF's 2.5 s on the test machine. Each ``src="data:image/...;base64,..."`` becomes a
    short ``loceval-embedded:N`` URL that only this render's fetcher answers, with the
    same bytes and media type; text that merely looks like a data URL stays as it is
    (the ``"`` around an attribute value is escaped anywhere else).
    """
    images: dict[str, tuple[str, bytes]] = {}

    def hoist(match: re.Match[bytes]) -> bytes:
        url = f"{_EMBEDDED_SCHEME}:{len(images)}"
        images[url] = (match.group(1).decode("ascii"), base64.b64decode(match.group(2)))
        return url.encode("ascii")

    return _EMBEDDED_SRC.sub(hoist, html).decode("utf-8"), images


def _embedded_fetcher(images: Mapping[str, tuple[str, bytes]]) -> object:
    """Return a WeasyPrint URL fetcher of ``images`` and ``data:`` URLs, and nothing else."""
    _weasyprint()  # imported once, under its lock, before the names are taken from it
    from weasyprint.urls import URLFetcher, URLFetcherResponse  # noqa: PLC0415

    class EmbeddedFetcher(URLFetcher):  # type: ignore[misc]  # WeasyPrint is untyped
        def fetch(self, url: str, headers: object = None) -> object:
            found = images.get(url)
            if found is None:
                return super().fetch(url, headers)
            media_type, body = found
            return URLFetcherResponse(url, body, {"Content-Type": media_type})

    return EmbeddedFetcher(allowed_protocols=("data",), fail_on_errors=True)


def layout_pdf(
    templates_dir: Path,
    typst_template: str,
    view: object,
    *,
    label: str,
    html: Callable[[], bytes],
) -> bytes:
    """Lay a view model out as an A4 PDF with the folder's engine (:func:`pdf_engine`).

    Args:
        templates_dir: the template folder.
        typst_template: the ``.typ`` template's name (Typst typesets it from ``view``).
        view: the view model.
        label: names the template in messages.
        html: renders the HTML WeasyPrint lays out, for a folder without ``typst_template``.

    Raises:
        ExportUnavailableError: the PDF's engine is missing.
        ExportError: the templates are missing or failed.
    """
    if pdf_engine(templates_dir, typst_template) == "typst":
        return typeset_pdf(templates_dir / typst_template, view, label=label)
    return html_to_pdf(html())


def render_view_pdf(view: ReportView, *, templates_dir: Path) -> bytes:
    """Lay a view model out as the report's A4 PDF.

    Typst typesets ``report.typ`` of the folder (figures as SVG: the view must have been
    built with ``image_format="svg"``); a folder without one has its HTML laid out by
    WeasyPrint (figures as PNG: ``image_format="png"``, see :func:`pdf_figure_format`).

    Raises:
        ExportUnavailableError: the PDF's engine is missing.
        ExportError: the templates are missing or failed.
    """
    return layout_pdf(
        templates_dir,
        PDF_TEMPLATE_NAME,
        view,
        label="report",
        html=lambda: render_view_html(view, templates_dir=templates_dir),
    )


def render_report(
    result: EvaluationResult,
    *,
    options: ExportOptions | None = None,
    templates_dir: Path | None = None,
    max_points: int = DEFAULT_MAX_POINTS,
) -> tuple[bytes, bytes]:
    """Render the report as HTML and PDF, drawing each figure once for both.

    The HTML embeds the plots as SVG, and so does the PDF Typst typesets (as vectors);
    the PDF of HTML templates of one's own, laid out by WeasyPrint, embeds them as 200 dpi
    PNG (WeasyPrint draws matplotlib's SVG slowly).

    Args:
        result: the evaluation.
        options: title and evaluation id (defaults otherwise).
        templates_dir: the template folder; default ``options.templates_dir``, else the
            repository's ``templates/``.
        max_points: most vertices drawn per plotted line (drawing only).

    Returns:
        ``(html, pdf)`` as bytes.

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or the PDF's engine is missing.
        ExportError: the templates are missing or the layout failed.
    """
    options = options or ExportOptions()
    folder = _templates_dir(options, templates_dir)
    formats = report_figure_formats(folder, ("report.html", "report.pdf"))
    plots = render_report_plots(result, options, formats=formats, max_points=max_points)
    html = render_report_html(result, options, plots=plots, templates_dir=folder)
    return html, render_report_pdf(result, options, plots=plots, templates_dir=folder)


def report_figure_formats(templates_dir: Path, names: Iterable[str]) -> tuple[ImageFormat, ...]:
    """Return the encodings the reports ``names`` of a folder embed their figures in.

    ``report.html`` embeds SVG; ``report.pdf`` SVG too when Typst typesets it, PNG when
    WeasyPrint lays out the folder's HTML.
    """
    wanted = set(names)
    formats: list[ImageFormat] = []
    if "report.html" in wanted:
        formats.append("svg")
    if "report.pdf" in wanted:
        formats.append(pdf_figure_format(templates_dir))
    return tuple(dict.fromkeys(formats))


def render_report_html(
    result: EvaluationResult,
    options: ExportOptions,
    *,
    plots: ReportPlots | None = None,
    templates_dir: Path | None = None,
) -> bytes:
    """Render ``report.html``: one self-contained file (the ARTIFACTS exporter).

    Args:
        result: the evaluation.
        options: title, evaluation id, templates folder.
        plots: the figures already drawn, with their SVG (:func:`render_report_plots`);
            default: draw them here.
        templates_dir: the template folder; default ``options.templates_dir``, else the
            repository's ``templates/``.

    Raises:
        ExportUnavailableError: Jinja2 or matplotlib is missing.
        ExportError: the templates are missing or broken.
    """
    folder = _templates_dir(options, templates_dir)
    return render_view_html(
        build_report_view(result, options, plots=plots, image_format="svg"),
        templates_dir=folder,
        viewer=viewer_fragment(result, options, templates_dir=folder),
    )


def render_report_pdf(
    result: EvaluationResult,
    options: ExportOptions,
    *,
    plots: ReportPlots | None = None,
    templates_dir: Path | None = None,
) -> bytes:
    """Render ``report.pdf``: the same report on A4 pages (the ARTIFACTS exporter).

    Typeset by Typst from ``report.typ`` with the figures as vectors, or, for a folder of
    HTML templates only, laid out from the HTML by WeasyPrint with PNG figures.

    Args:
        result: the evaluation.
        options: title, evaluation id, templates folder.
        plots: the figures already drawn, in the PDF's format (:func:`pdf_figure_format`;
            :func:`render_report_plots`); default: draw them here.
        templates_dir: the template folder; default ``options.templates_dir``, else the
            repository's ``templates/``.

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or the PDF's engine is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates_dir(options, templates_dir)
    check_pdf(folder)  # before drawing anything: without its engine there is no PDF to draw for
    view = build_report_view(result, options, plots=plots, image_format=pdf_figure_format(folder))
    return render_view_pdf(view, templates_dir=folder)
