"""The API's documentation page, ``/docs``, with Swagger UI's files served by the service.

FastAPI's own ``/docs`` loads Swagger UI from a CDN, which a site network without internet
cannot reach. Here the page's script, stylesheet and icon are Swagger UI 5 (Apache-2.0),
vendored in ``templates/web/vendor/swagger-ui/`` at the version its ``VERSION`` file pins
(``make vendor-swagger-ui`` refreshes it): version 5 renders the OpenAPI 3.1 document FastAPI
writes, which the 4.x of the ``swagger-ui-bundle`` package could not.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Final

from fastapi import APIRouter, FastAPI, HTTPException, Request
from fastapi.openapi.docs import get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import HTMLResponse, Response

from service.schemas.examples import BY_SCHEMA

__all__ = ["ASSETS_PREFIX", "SWAGGER_UI_DIR", "document_examples", "router"]

ASSETS_PREFIX: Final = "/docs/assets"
SWAGGER_UI_DIR: Final = Path("web/vendor/swagger-ui")
"""Swagger UI's files, relative to the templates folder."""
_ASSETS: Final = {
    "swagger-ui-bundle.js": "text/javascript; charset=utf-8",
    "swagger-ui.css": "text/css; charset=utf-8",
    "favicon-32x32.png": "image/png",
}
_CACHE: Final = {"Cache-Control": "public, max-age=86400", "X-Content-Type-Options": "nosniff"}

router = APIRouter(include_in_schema=False)


def document_examples(app: FastAPI) -> None:
    """Give the answers' schemas in the app's OpenAPI document their examples, nulls kept.

    FastAPI writes the document without any ``null`` (``exclude_none``), so an example of a
    real answer set on a model would lose its ``"error": null`` and no longer be one; they
    are set here, once, on the written document (:data:`service.schemas.examples.BY_SCHEMA`).
    """
    write = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            document = write()
            schemas = document["components"]["schemas"]
            for name, example in BY_SCHEMA.items():
                schemas[name]["examples"] = [example]
        return app.openapi_schema or {}

    app.openapi = openapi  # type: ignore[method-assign]


def _assets_dir(request: Request) -> Path:
    """Return the folder of Swagger UI's files in the running app's templates folder."""
    return Path(request.app.state.settings.templates_dir) / SWAGGER_UI_DIR


@router.get("/docs", response_class=HTMLResponse)
def swagger_ui(request: Request) -> HTMLResponse:
    """Return Swagger UI's page, pointing at this service's copies of its files.

    Args:
        request: The incoming request; its app names the title and the OpenAPI document.

    Returns:
        The page, with no address outside this service.
    """
    root = request.scope.get("root_path", "")
    return get_swagger_ui_html(
        openapi_url=f"{root}{request.app.openapi_url}",
        title=f"{request.app.title} — API documentation",
        swagger_js_url=f"{root}{ASSETS_PREFIX}/swagger-ui-bundle.js",
        swagger_css_url=f"{root}{ASSETS_PREFIX}/swagger-ui.css",
        swagger_favicon_url=f"{root}{ASSETS_PREFIX}/favicon-32x32.png",
        oauth2_redirect_url=f"{root}/docs/oauth2-redirect",
    )


@router.get("/docs/oauth2-redirect", response_class=HTMLResponse)
def swagger_ui_redirect() -> HTMLResponse:
    """Return Swagger UI's OAuth2 redirect page (part of the UI, unused by API keys).

    Returns:
        The redirect page.
    """
    return get_swagger_ui_oauth2_redirect_html()


@router.get(ASSETS_PREFIX + "/{name}")
def swagger_asset(request: Request, name: str) -> Response:
    """Return one of Swagger UI's files.

    Args:
        request: The incoming request; its app's settings name the templates folder.
        name: The file's name; only the page's three files are served.

    Returns:
        The file with its media type, cacheable for a day.

    Raises:
        HTTPException: 404 for any other name, or when the templates folder lacks it.
    """
    media_type = _ASSETS.get(name)
    if media_type is None:
        raise HTTPException(status_code=404, detail=f"{name} is not a file of the docs page")
    try:
        content = (_assets_dir(request) / name).read_bytes()
    except FileNotFoundError as err:  # a deployment without the templates folder
        raise HTTPException(
            status_code=404,
            detail=f"Swagger UI's {name} is not installed: the service's templates folder "
            f"lacks {SWAGGER_UI_DIR}/ (LOCEVAL_TEMPLATES_DIR names the folder)",
        ) from err
    return Response(content, media_type=media_type, headers=_CACHE)
