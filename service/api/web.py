"""The browser page: one HTML page, its script and its stylesheet, served by the API itself.

No build step and nothing from the internet: the page is a Jinja2 template and two static
files in ``templates/web/``. The page talks to ``/api/v1`` with the key the user pastes,
so these routes need no key themselves and carry nothing secret.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Final

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import HTMLResponse, Response
from jinja2 import Environment, FileSystemLoader

from exporters import ARTIFACTS
from exporters.cad.site import BUILDING_SUFFIXES
from exporters.report import pdf_available
from exporters.summary.render import SUMMARY_PDF_TEMPLATE_NAME
from loceval import __version__
from loceval.core.display import shown_text
from loceval.options import option
from loceval.readers.source import TrajectoryFormat
from service.schemas.evaluations import options_public

__all__ = ["TUS_JS_CLIENT_DIR", "router"]

router = APIRouter(include_in_schema=False)

_WEB_DIR: Final = "web"
_PAGE: Final = f"{_WEB_DIR}/index.html.j2"
_HEADERS: Final = {
    "Cache-Control": "no-cache",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}
_ASSETS: Final = {
    "app.js": "text/javascript; charset=utf-8",
    "app.css": "text/css; charset=utf-8",
    "vendor/tus-js-client/tus.min.js": "text/javascript; charset=utf-8",
}
TUS_JS_CLIENT_DIR: Final = Path(_WEB_DIR) / "vendor" / "tus-js-client"
"""The vendored tus-js-client (``make vendor-tus-js-client``; see its README), relative to the
templates folder: the page's resumable uploads."""


@lru_cache(maxsize=8)
def _environment(templates_dir: Path) -> Environment:
    """Return the Jinja2 environment of a templates folder (one per folder, reused)."""
    return Environment(loader=FileSystemLoader(templates_dir), autoescape=True, finalize=shown_text)


def _templates_dir(request: Request) -> Path:
    """Return the templates folder of the running app's settings."""
    return Path(request.app.state.settings.templates_dir)


def _pdf_reports(templates_dir: Path) -> bool:
    """Whether this server writes the report's and the summary's PDFs.

    Always with the repository's templates (Typst typesets them); a folder of HTML templates
    of one's own needs WeasyPrint and pango to lay them out.
    """
    return pdf_available(templates_dir) and pdf_available(templates_dir, SUMMARY_PDF_TEMPLATE_NAME)


@router.get("/", response_class=HTMLResponse, include_in_schema=False)
def index(request: Request) -> HTMLResponse:
    """Return the browser page.

    Args:
        request: The incoming request; its app's settings name the templates folder.

    Returns:
        The rendered page, never cached without a check. ``<body data-pdf-reports>`` says
        whether this server can write PDFs (always with the repository's templates; HTML
        templates of one's own need WeasyPrint and pango, checked once per process): when it
        cannot, the page asks for no ``report.pdf`` or ``summary.pdf``.
        ``<body data-artifacts>`` lists the files an evaluation can make (the server's
        :data:`exporters.ARTIFACTS`, in order), the upload hint names the building model
        formats and the up-axis choice offers the option table's choices, and
        ``<body data-options>`` is the API's options document (``GET /api/v1/options``),
        from which the form takes its fields' bounds, choices and help and makes a field
        for every option it does not place itself; ``<body data-formats>`` names the
        readers' formats and their shapes, which the page offers when an upload is
        unreadable; so the page copies none of these.
    """
    template = _environment(_templates_dir(request)).get_template(_PAGE)
    html = template.render(
        version=__version__,
        pdf_reports=_pdf_reports(_templates_dir(request)),
        artifacts=list(ARTIFACTS),
        building_formats=", ".join(s.lstrip(".").upper() for s in BUILDING_SUFFIXES),
        building_up=option("building_up"),
        formats=[{"name": f.value, "shape": f.shape} for f in TrajectoryFormat],
        options=[item.model_dump() for item in options_public().items],
    )
    return HTMLResponse(
        html, headers={**_HEADERS, "X-Frame-Options": "DENY"}, media_type="text/html"
    )


def _asset(request: Request, name: str) -> Response:
    """Return one static file of the page with its media type."""
    path = _templates_dir(request) / _WEB_DIR / name
    try:
        content = path.read_bytes()
    except FileNotFoundError as err:  # a deployment without the templates folder
        raise HTTPException(status_code=404, detail=f"{name} is not installed") from err
    return Response(content, media_type=_ASSETS[name], headers=_HEADERS)


@router.get("/web/app.js", include_in_schema=False)
def app_js(request: Request) -> Response:
    """Return the page's script.

    Args:
        request: The incoming request; its app's settings name the templates folder.

    Returns:
        The script as ``text/javascript``.
    """
    return _asset(request, "app.js")


@router.get("/web/app.css", include_in_schema=False)
def app_css(request: Request) -> Response:
    """Return the page's stylesheet.

    Args:
        request: The incoming request; its app's settings name the templates folder.

    Returns:
        The stylesheet as ``text/css``.
    """
    return _asset(request, "app.css")


@router.get("/web/vendor/tus.min.js", include_in_schema=False)
def tus_js(request: Request) -> Response:
    """Return the vendored tus-js-client, the page's resumable upload client.

    Args:
        request: The incoming request; its app's settings name the templates folder.

    Returns:
        The browser bundle as ``text/javascript``, byte for byte as published.
    """
    return _asset(request, "vendor/tus-js-client/tus.min.js")
