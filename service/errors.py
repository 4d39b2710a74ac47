"""The service's errors and the one table that turns every error into a problem document.

Routes raise typed errors and contain no ``try/except`` for domain conditions; the handlers
here render them as ``application/problem+json`` (RFC 9457). Request validation, unknown
routes and wrong methods are rendered the same way, so a client parses one error shape.
"""

from __future__ import annotations

import json
import logging
import uuid
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, Final

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from exporters.errors import ExportUnavailableError
from loceval.core.display import display_text
from loceval.errors import (
    AlignmentError,
    AssociationError,
    InputError,
    LocevalError,
    MetricError,
)
from service.redact import register_private_root, scrub

__all__ = [
    "PROBLEM_JSON",
    "STATUS_BY_ERROR",
    "AuthenticationError",
    "ConflictError",
    "InsufficientStorageError",
    "InvalidFieldsError",
    "JobMemoryError",
    "JobTimeoutError",
    "NotFoundError",
    "NotReadyError",
    "ServiceUnavailableError",
    "StartupError",
    "UploadError",
    "UploadTooLargeError",
    "WebhookRefusedError",
    "WebhookUnresolvedError",
    "install_error_handlers",
    "internal_problem",
    "problem",
    "problem_for",
    "register_private_root",
    "scrub",
    "status_for",
]

logger = logging.getLogger(__name__)

PROBLEM_JSON: Final = "application/problem+json"
_METHODS: Final = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


class NotFoundError(LocevalError):
    """An id that this key's project does not have (another project's ids included)."""

    code: ClassVar[str] = "not_found"


class NotReadyError(LocevalError):
    """The evaluation has not succeeded (yet), so it has no artifacts."""

    code: ClassVar[str] = "evaluation.not_ready"


class ConflictError(LocevalError):
    """The request conflicts with the state of a resource (deleting a dataset in use)."""

    code: ClassVar[str] = "conflict"


class AuthenticationError(LocevalError):
    """No API key, or one that is unknown or revoked."""

    code: ClassVar[str] = "auth.unauthorized"


class InvalidFieldsError(InputError):
    """Fields of a request that do not validate, found below the routes.

    A form's options or an upload's tags: answered exactly like FastAPI's own request
    validation, a 422 whose ``errors`` name each field's place (``options.max_dt_s``,
    ``tags``), so the resource modules raise no HTTP type.
    """

    code: ClassVar[str] = "request.invalid"

    def __init__(self, errors: Sequence[Mapping[str, Any]]) -> None:
        """Keep pydantic-style errors (``loc``, ``msg``, ``type``) for the problem document."""
        self.errors = errors
        super().__init__("; ".join(str(e.get("msg", "")) for e in errors) or "not valid")


class UploadError(InputError):
    """The upload request itself is malformed (not multipart, no file field, ...)."""

    code: ClassVar[str] = "upload.invalid"


class UploadTooLargeError(UploadError):
    """The upload is larger than the configured limit."""

    code: ClassVar[str] = "upload.too_large"


class WebhookRefusedError(InputError):
    """A webhook URL the service will not post to: its form, or an internal address."""

    code: ClassVar[str] = "schedule.webhook_refused"


class WebhookUnresolvedError(WebhookRefusedError):
    """A webhook host that does not resolve (at delivery: retried, it may be temporary)."""

    code: ClassVar[str] = "schedule.webhook_unresolved"


class InsufficientStorageError(LocevalError):
    """The data directory is nearly full: an upload would leave less than the set reserve."""

    code: ClassVar[str] = "storage.full"


class JobTimeoutError(InputError):
    """The job ran longer than ``job_timeout_s`` and was stopped."""

    code: ClassVar[str] = "job.timeout"


class JobMemoryError(InputError):
    """The job needed more memory than ``job_memory_mb`` (or than the server had)."""

    code: ClassVar[str] = "job.out_of_memory"


class ServiceUnavailableError(LocevalError):
    """The database or the queue cannot be reached."""

    code: ClassVar[str] = "service.unavailable"


class StartupError(ServiceUnavailableError):
    """The service cannot start: its data directory or database is not usable as it is."""

    code: ClassVar[str] = "service.startup"


STATUS_BY_ERROR: Final[Mapping[type[LocevalError], int]] = {
    UploadTooLargeError: 413,
    UploadError: 400,
    InputError: 422,
    AssociationError: 422,
    AlignmentError: 422,
    MetricError: 422,
    NotFoundError: 404,
    NotReadyError: 409,
    ConflictError: 409,
    AuthenticationError: 401,
    ServiceUnavailableError: 503,
    InsufficientStorageError: 507,
    ExportUnavailableError: 501,
    LocevalError: 500,
}
"""Status of each error class; the most specific class in the MRO wins."""


def status_for(exc: LocevalError) -> int:
    """Return the status of the most specific mapped class in the exception's MRO."""
    return next(STATUS_BY_ERROR[c] for c in type(exc).__mro__ if c in STATUS_BY_ERROR)


def problem(
    status: int,
    type_: str,
    title: str,
    detail: str,
    **extra: Any,  # noqa: ANN401
) -> dict[str, Any]:
    """Return a problem document."""
    return {"type": type_, "title": title, "status": status, "detail": detail, **extra}


def problem_for(exc: LocevalError) -> dict[str, Any]:
    """Return the problem document of a domain error (also stored with failed jobs).

    This is the one place where messages are scrubbed of server paths (the data directory,
    temporary and extraction folders: :func:`service.redact.scrub`) and of control
    characters (:func:`loceval.core.display.display_text`): every problem a
    client sees, from a route or stored with a failed job, is built here. An error about an
    option names it as the API does: ``options.max_dt_s: ...`` in the detail, and
    ``"option": "options.max_dt_s"`` as a member a client can point at.
    """
    detail = display_text(scrub(str(exc), all_temp=True), one_line=False)
    if exc.option is None:
        return problem(status_for(exc), exc.code, type(exc).__name__, detail)
    name = f"options.{exc.option}"
    detail = f"{name}: {detail}"
    if exc.suggest is not None:
        detail += f" Set {name} to {json.dumps(exc.suggest)}."
    return problem(status_for(exc), exc.code, type(exc).__name__, detail, option=name)


def internal_problem(error_id: str | None = None) -> dict[str, Any]:
    """Return the problem document of a bug; the details are in the log under error_id."""
    error_id = error_id or uuid.uuid4().hex[:12]
    return problem(
        500,
        "internal",
        "InternalError",
        f"Internal error (error_id={error_id}); this is a bug, please report it with the id.",
        error_id=error_id,
    )


def _response(body: Mapping[str, Any], headers: Mapping[str, str] | None = None) -> JSONResponse:
    return JSONResponse(
        jsonable_encoder(body),
        status_code=int(body["status"]),
        media_type=PROBLEM_JSON,
        headers=dict(headers or {}),
    )


async def _handle_loceval_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, LocevalError)  # noqa: S101  (registered for this class only)
    body = problem_for(exc)
    headers = {"WWW-Authenticate": "Bearer"} if isinstance(exc, AuthenticationError) else None
    if body["status"] >= 500:
        logger.error("%s: %s", type(exc).__name__, exc)
    return _response(body, headers)


async def _handle_validation_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError | InvalidFieldsError)  # noqa: S101
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
    headers = dict(exc.headers or {})
    if exc.status_code == 405 and (allowed := _allowed_methods(request)):
        headers["Allow"] = allowed
        detail = f"This endpoint answers to {allowed} only."
    body = problem(exc.status_code, "http", titles.get(exc.status_code, "HTTPError"), detail)
    return _response(body, headers)


async def _handle_bug(_request: Request, exc: Exception) -> JSONResponse:
    error_id = uuid.uuid4().hex[:12]
    logger.error("Unhandled error (error_id=%s)", error_id, exc_info=exc)
    return _response(internal_problem(error_id))


def install_error_handlers(app: FastAPI) -> None:
    """Register the problem+json handlers."""
    app.add_exception_handler(LocevalError, _handle_loceval_error)
    app.add_exception_handler(RequestValidationError, _handle_validation_error)
    app.add_exception_handler(InvalidFieldsError, _handle_validation_error)
    app.add_exception_handler(StarletteHTTPException, _handle_http_error)
    app.add_exception_handler(Exception, _handle_bug)
