"""The service's errors and the one table that turns every error into a problem document.

Routes raise typed errors and contain no ``try/except`` for domain conditions; the handlers
in :mod:`service.api.problems` render them as ``application/problem+json`` (RFC 9457) with
:func:`problem_for`, which jobs use too for the errors they store. Plain Python: the
blob stores, the uploads and the jobs raise these without importing a web framework.
"""

from __future__ import annotations

import errno
import json
import sqlite3
import uuid
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar, Final

from exporters.errors import ExportUnavailableError
from loceval.core.display import display_text
from loceval.errors import (
    AlignmentError,
    AssociationError,
    InputError,
    LocevalError,
    MetricError,
)
from service.redact import scrub

__all__ = [
    "PROBLEM_JSON",
    "RETRY_AFTER_S",
    "STATUS_BY_ERROR",
    "STORAGE_FULL_DETAIL",
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
    "TusVersionError",
    "UploadChecksumError",
    "UploadError",
    "UploadLockedError",
    "UploadMediaTypeError",
    "UploadOffsetError",
    "UploadTooLargeError",
    "WebhookRefusedError",
    "WebhookUnresolvedError",
    "internal_problem",
    "is_storage_full",
    "problem",
    "problem_for",
    "problem_headers",
    "status_for",
]

PROBLEM_JSON: Final = "application/problem+json"
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


class UploadChecksumError(UploadError):
    """A resumable upload's request whose bytes do not match its ``Upload-Checksum``."""

    code: ClassVar[str] = "upload.checksum_mismatch"


class UploadMediaTypeError(UploadError):
    """A resumable upload's request whose body is not ``application/offset+octet-stream``."""

    code: ClassVar[str] = "upload.media_type"


class TusVersionError(UploadError):
    """A resumable upload's request without ``Tus-Resumable: 1.0.0`` (the protocol's version)."""

    code: ClassVar[str] = "upload.tus_version"


class UploadOffsetError(ConflictError):
    """A resumable upload's request whose ``Upload-Offset`` is not where the upload stands."""

    code: ClassVar[str] = "upload.offset_mismatch"


class UploadLockedError(ConflictError):
    """A resumable upload another request is writing to at the moment."""

    code: ClassVar[str] = "upload.locked"


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
    UploadChecksumError: 460,  # tus 1.0's checksum extension: "460 Checksum Mismatch"
    UploadMediaTypeError: 415,
    TusVersionError: 412,
    UploadOffsetError: 409,
    UploadLockedError: 423,
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


def problem_for(exc: LocevalError, *, private: Iterable[Path] = ()) -> dict[str, Any]:
    """Return the problem document of a domain error (also stored with failed jobs).

    This is the one place where messages are scrubbed of server paths (the runtime's data
    directory, given as ``private``; temporary and extraction folders:
    :func:`service.redact.scrub`) and of control characters
    (:func:`loceval.core.display.display_text`): every problem a client sees, from a route or
    stored with a failed job, is built here. An error about an option names it as the API
    does: ``options.max_dt_s: ...`` in the detail, and ``"option": "options.max_dt_s"`` as a
    member a client can point at.

    Args:
        exc: the error.
        private: the server's folders no client may see
            (:attr:`service.runtime.Runtime.private_roots`).
    """
    detail = display_text(scrub(str(exc), private=private, all_temp=True), one_line=False)
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
