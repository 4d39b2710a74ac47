"""The problem-document handlers: every error a route lets through, as problem+json.

Routes raise typed errors (:mod:`service.errors`) and contain no ``try/except`` for domain
conditions; the handlers here render them as ``application/problem+json`` (RFC 9457) with
:func:`service.errors.problem_for`, scrubbed of the runtime's private folders. Request
validation, unknown routes and wrong methods are rendered the same way, so a client parses
one error shape.
"""

from __future__ import annotations

import logging
import sqlite3
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Final

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import SQLAlchemyError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from loceval.errors import LocevalError
from service.errors import (
    PROBLEM_JSON,
    STORAGE_FULL_DETAIL,
    InsufficientStorageError,
    InvalidFieldsError,
    ServiceUnavailableError,
    internal_problem,
    is_storage_full,
    problem,
    problem_for,
    problem_headers,
)

__all__ = ["install_error_handlers", "private_roots"]

logger = logging.getLogger("service.errors")  # the log lines of errors keep their logger's name

_METHODS: Final = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def private_roots(app: Any) -> tuple[Path, ...]:  # noqa: ANN401  (Starlette's app)
    """Return the private folders of the app's runtime (none before it is set)."""
    runtime = getattr(app.state, "runtime", None)
    return () if runtime is None else tuple(runtime.private_roots)


def _response(body: Mapping[str, Any], headers: Mapping[str, str] | None = None) -> JSONResponse:
    return JSONResponse(
        jsonable_encoder(body),
        status_code=int(body["status"]),
        media_type=PROBLEM_JSON,
        headers=dict(headers or {}),
    )


async def _handle_loceval_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, LocevalError)  # noqa: S101  (registered for this class only)
    body = problem_for(exc, private=private_roots(request.app))
    if body["status"] >= 500:
        logger.error("%s: %s", type(exc).__name__, exc)
    return _response(body, problem_headers(exc))


async def _handle_validation_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError | InvalidFieldsError)  # noqa: S101
    if isinstance(exc, InvalidFieldsError) and not exc.errors:
        return await _handle_loceval_error(request, exc)
    found = exc.errors() if isinstance(exc, RequestValidationError) else exc.errors
    errors = [
        {
            "loc": list(e.get("loc", ())),
            "msg": str(e.get("msg", "")),
            "type": str(e.get("type", "")),
        }
        for e in found
    ]
    where = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in errors[:5])
    detail = f"The request is not valid: {where}." if where else "The request is not valid."
    body = problem(422, "request.invalid", "RequestValidationError", detail, errors=errors)
    return _response(body)


def _allowed_methods(request: Request) -> str:
    """Return every method the request's path answers to (Starlette names one route's only)."""
    routes = request.app.router.routes
    allowed = [
        method
        for method in _METHODS
        if any(r.matches({**request.scope, "method": method})[0] is Match.FULL for r in routes)
    ]
    return ", ".join(allowed)


def _other_slash_form(request: Request) -> str | None:
    """Return the request's path with its trailing slash toggled, if a route answers that.

    Only the path is returned, never a URL: the request's Host header is not trusted.
    """
    path = str(request.scope.get("path", ""))
    if path in {"", "/"}:
        return None
    other = path[:-1] if path.endswith("/") else path + "/"
    routes = request.app.router.routes
    scope = {**request.scope, "path": other}
    if any(route.matches(scope)[0] is not Match.NONE for route in routes):
        return other
    return None


async def _handle_http_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)  # noqa: S101
    if exc.status_code == 400 and isinstance(exc.__cause__, UnicodeDecodeError):
        # FastAPI's 400 for a JSON body that is not UTF-8: the same 422 as any undecodable JSON.
        msg = "JSON decode error (the body is not UTF-8)"
        errors = [{"loc": ["body"], "msg": msg, "type": "json_invalid"}]
        detail = f"The request is not valid: body: {msg}."
        return _response(
            problem(422, "request.invalid", "RequestValidationError", detail, errors=errors)
        )
    titles = {404: "NotFound", 405: "MethodNotAllowed", 401: "Unauthorized"}
    detail = str(exc.detail)
    if exc.status_code == 404 and detail == "Not Found":
        detail = "No such endpoint; the API is described at /docs."
        if other := _other_slash_form(request):
            detail = f"No such endpoint; did you mean {other} (no redirect is sent)?"
    headers = dict(exc.headers or {})
    if exc.status_code == 405 and (allowed := _allowed_methods(request)):
        headers["Allow"] = allowed
        detail = f"This endpoint answers to {allowed} only."
    body = problem(exc.status_code, "http", titles.get(exc.status_code, "HTTPError"), detail)
    return _response(body, headers)


async def _handle_backend_error(request: Request, exc: Exception) -> JSONResponse:
    """A database or file error that reached a route: a full disk is 507, else a bug."""
    if is_storage_full(exc):
        logger.error("Refused a request: the disk is full (%s)", type(exc).__name__)
        return _response(
            problem(507, InsufficientStorageError.code, "InsufficientStorage", STORAGE_FULL_DETAIL)
        )
    return await _handle_bug(request, exc)


async def _handle_bug(_request: Request, exc: Exception) -> JSONResponse:
    error_id = uuid.uuid4().hex[:12]
    logger.error("Unhandled error (error_id=%s)", error_id, exc_info=exc)
    return _response(internal_problem(error_id))


def install_error_handlers(
    app: FastAPI,
    *,
    outages: tuple[type[Exception], ...] = (),
    unavailable: Callable[[Exception], ServiceUnavailableError] | None = None,
) -> None:
    """Register the problem+json handlers.

    Args:
        app: the application.
        outages: the backends' errors of an outage (:data:`service.adapters.OUTAGE_ERRORS`)
            that a route may let through: answered 503 with ``Retry-After``, like
            :class:`ServiceUnavailableError`, not 500. (Registered by class, they are handled
            inside the app: the kept-alive connection stays open, unlike after a 500.)
        unavailable: turns such an error into the 503 error
            (:func:`service.adapters.unavailable`).
    """
    app.add_exception_handler(LocevalError, _handle_loceval_error)
    if unavailable is not None:
        convert = unavailable

        async def _handle_outage(request: Request, exc: Exception) -> JSONResponse:
            if is_storage_full(exc):  # SQLite's "disk is full" is an OperationalError too
                return await _handle_backend_error(request, exc)
            return await _handle_loceval_error(request, convert(exc))

        for outage in outages:
            app.add_exception_handler(outage, _handle_outage)
    app.add_exception_handler(RequestValidationError, _handle_validation_error)
    app.add_exception_handler(InvalidFieldsError, _handle_validation_error)
    app.add_exception_handler(StarletteHTTPException, _handle_http_error)
    for backend_error in (SQLAlchemyError, sqlite3.Error, OSError):
        app.add_exception_handler(backend_error, _handle_backend_error)
    app.add_exception_handler(Exception, _handle_bug)
