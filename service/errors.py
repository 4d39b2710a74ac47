"""The service's errors and the one table that turns every error into a problem document.

Routes raise typed errors and contain no ``try/except`` for domain conditions; the handlers
here render them as ``application/problem+json`` (RFC 9457). Request validation, unknown
routes and wrong methods are rendered the same way, so a client parses one error shape.
"""

from __future__ import annotations

import errno
import json
import logging
import sqlite3
import uuid
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Final

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import SQLAlchemyError
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
    "RETRY_AFTER_S",
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
    "StoreUnavailableError",
    "UploadError",
    "UploadTooLargeError",
    "WebhookRefusedError",
    "WebhookUnresolvedError",
    "install_error_handlers",
    "internal_problem",
    "is_storage_full",
    "problem",
    "problem_for",
    "problem_headers",
    "register_private_root",
    "scrub",
    "status_for",
]

logger = logging.getLogger(__name__)

PROBLEM_JSON: Final = "application/problem+json"
_METHODS: Final = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")
RETRY_AFTER_S: Final = 5
"""The ``Retry-After`` of a 503: a restarting database or queue is back within seconds."""


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

    def __init__(
        self,
        message: str = "",
        *,
        errors: Sequence[Mapping[str, Any]] = (),
        option: str | None = None,
        suggest: str | None = None,
    ) -> None:
        """Keep pydantic-style ``errors`` (``loc``, ``msg``, ``type``) for the problem document.

        Without ``errors`` it is answered like any other error: ``message`` is the detail.
        """
        self.errors = list(errors)
        text = message or "; ".join(str(e.get("msg", "")) for e in self.errors)
        super().__init__(text or "The request is not valid.", option=option, suggest=suggest)


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


class StoreUnavailableError(ServiceUnavailableError):
    """The object store cannot be reached or refuses to serve (an outage, not the input's fault).

    A job that meets it is put back in the queue, not failed (:mod:`service.jobs.tracking`).
    """

    code: ClassVar[str] = "service.unavailable"


class StartupError(ServiceUnavailableError):
    """The service cannot start: its data directory or database is not usable as it is."""

    code: ClassVar[str] = "service.startup"


_FULL_ERRNOS: Final = frozenset({errno.ENOSPC, errno.EDQUOT})
_PG_DISK_FULL: Final = "53100"  # PostgreSQL's disk_full ("could not extend file")
STORAGE_FULL_DETAIL: Final = (
    "The server's disk is full, so nothing of this request was saved. Ask the server's "
    "administrator to free space where the data directory (LOCEVAL_DATA_DIR) and the "
    "database live (remove other files, or give the volume more space; then delete old "
    "evaluations or datasets, or set LOCEVAL_RETENTION_DAYS, so it stays free), and send the "
    "request again."
)
"""What a request refused for a full disk is told."""


def is_storage_full(exc: BaseException) -> bool:
    """Whether an error, or one it was raised from, means the disk is full.

    SQLite's ``SQLITE_FULL`` ("database or disk is full"), PostgreSQL's ``disk_full``
    (SQLSTATE 53100; psycopg's ``DiskFull``), and a write that failed with ENOSPC or EDQUOT;
    SQLAlchemy and huey raise them from their own errors, so the chain is followed.
    """
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, OSError) and current.errno in _FULL_ERRNOS:
            return True
        if isinstance(current, sqlite3.Error) and (
            getattr(current, "sqlite_errorcode", None) == sqlite3.SQLITE_FULL
            or "database or disk is full" in str(current)
        ):
            return True
        if getattr(current, "sqlstate", None) == _PG_DISK_FULL:
            return True
        current = getattr(current, "orig", None) or current.__cause__ or current.__context__
    return False


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


def problem_headers(exc: LocevalError) -> dict[str, str]:
    """Return the headers that go with an error's problem document.

    A 401 names the scheme (``WWW-Authenticate``); a 503 says when to try again
    (``Retry-After``), as ``/readyz`` does while the database or the queue is away.
    """
    if isinstance(exc, AuthenticationError):
        return {"WWW-Authenticate": "Bearer"}
    if isinstance(exc, ServiceUnavailableError) and not isinstance(exc, StartupError):
        return {"Retry-After": str(RETRY_AFTER_S)}
    return {}


async def _handle_loceval_error(_request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, LocevalError)  # noqa: S101  (registered for this class only)
    body = problem_for(exc)
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
