"""OpenAPI descriptions of the problem documents each route can answer with.

Each status is shown in ``/docs`` with an answer the service gives under it (its ``type``,
``title`` and ``status`` those of the error class that makes it), not one example for all:
a 401 example is a 401 problem.
"""

from __future__ import annotations

from typing import Any, Final

from loceval.errors import LocevalError, ReaderError
from service.errors import (
    PROBLEM_JSON,
    STORAGE_FULL_DETAIL,
    AuthenticationError,
    ConflictError,
    InsufficientStorageError,
    NotFoundError,
    ServiceUnavailableError,
    TusVersionError,
    UploadChecksumError,
    UploadError,
    UploadLockedError,
    UploadMediaTypeError,
    UploadTooLargeError,
)

__all__ = ["EXAMPLES", "UNREADABLE", "not_found", "problem_example", "problems"]

_DESCRIPTIONS = {
    400: "malformed request (not multipart, truncated body)",
    401: "no API key, or an unknown or revoked one",
    404: "no such resource in this key's project",
    409: "conflict with the resource's state (a resumable upload: Upload-Offset is not "
    "where it stands)",
    412: "a resumable upload's request without 'Tus-Resumable: 1.0.0'",
    413: "upload larger than the limit",
    415: "a resumable upload's bytes without 'Content-Type: application/offset+octet-stream'",
    423: "another request is writing to this resumable upload (ask its offset, go on)",
    460: "the request's bytes do not match its Upload-Checksum (nothing was kept)",
    422: "invalid request or unusable input (the detail says what to do)",
    503: "database or queue unreachable",
    507: "the server's storage is full or nearly so: nothing was saved (the detail says "
    "what to free)",
}
_PROBLEM_SCHEMA: Final = {"$ref": "#/components/schemas/Problem"}


def problem_example(error: type[LocevalError], status: int, detail: str) -> dict[str, Any]:
    """Return the problem document the service answers for ``error`` (``type`` its code)."""
    return {"type": error.code, "title": error.__name__, "status": status, "detail": detail}


def not_found(plural: str, row_id: str) -> dict[str, Any]:
    """Return the 404 of a resource id that is not in the key's project."""
    detail = f"No {plural[:-1]} {row_id!r} in this project; list them with GET /{plural}."
    return problem_example(NotFoundError, 404, detail)


_EVALUATION_ID: Final = "297a1e94-c86c-4e41-a598-ddbfae842cde"
EXAMPLES: Final[dict[int, dict[str, Any]]] = {
    400: problem_example(
        UploadError,
        400,
        "Send the upload as multipart/form-data with the file in the field 'file' "
        "(curl -F FIELD=@FILE).",
    ),
    401: problem_example(
        AuthenticationError,
        401,
        "This endpoint needs an API key: send the header 'Authorization: Bearer KEY' "
        "(loceval keys create --project NAME prints one).",
    ),
    404: not_found("evaluations", _EVALUATION_ID),
    409: problem_example(
        ConflictError,
        409,
        f"Evaluation {_EVALUATION_ID!r} is running and cannot be deleted until it has "
        "finished; poll GET /evaluations/{id} and delete it once it has succeeded or failed.",
    ),
    413: problem_example(
        UploadTooLargeError,
        413,
        "The upload is larger than the limit of 4,295 MB; split the recording, or raise "
        "LOCEVAL_MAX_UPLOAD_BYTES on the server.",
    ),
    422: {
        "type": "request.invalid",
        "title": "RequestValidationError",
        "status": 422,
        "detail": "The request is not valid: query.limit: Input should be less than or equal "
        "to 500.",
        "errors": [
            {
                "loc": ["query", "limit"],
                "msg": "Input should be less than or equal to 500",
                "type": "less_than_equal",
            }
        ],
    },
    412: problem_example(
        TusVersionError,
        412,
        "This server speaks tus 1.0.0, and the request has no Tus-Resumable header; send "
        "'Tus-Resumable: 1.0.0' (every tus client does).",
    ),
    415: problem_example(
        UploadMediaTypeError,
        415,
        "Send the upload's bytes with 'Content-Type: application/offset+octet-stream'.",
    ),
    423: problem_example(
        UploadLockedError,
        423,
        "Another request is writing to this upload at the moment; ask its offset again "
        "(HEAD) in a moment and continue from there.",
    ),
    460: problem_example(
        UploadChecksumError,
        460,
        "The request's bytes do not match its Upload-Checksum (sha1); nothing of it was "
        "kept: send them again from the same offset.",
    ),
    503: problem_example(
        ServiceUnavailableError,
        503,
        "The metadata database cannot be reached (OperationalError); try again in a minute "
        "(GET /readyz shows when it is back).",
    ),
    507: problem_example(InsufficientStorageError, 507, STORAGE_FULL_DETAIL),
}
"""An answer of each status, as ``/docs`` shows it (a route may show its own instead)."""

UNREADABLE: Final = problem_example(
    ReaderError, 422, "run.mcap: no topic '/odom'; the bag has /amcl_pose, /tf."
)
"""The 422 of a route that reads a recording: the input cannot be used."""


def problems(
    *statuses: int, keyed: bool = True, examples: dict[int, dict[str, Any]] | None = None
) -> dict[int | str, dict[str, Any]]:
    """Return the ``responses=`` entries of these statuses, as problem+json with an example.

    Args:
        statuses: the statuses besides 401 and 422.
        keyed: the route needs an API key (it may answer 401); a route without one may
            still answer 422 for a malformed request.
        examples: this route's own example of a status, instead of :data:`EXAMPLES`'.
    """
    shown = {**EXAMPLES, **(examples or {})}
    return {
        status: {
            "description": _DESCRIPTIONS[status],
            "content": {PROBLEM_JSON: {"schema": _PROBLEM_SCHEMA, "example": shown[status]}},
        }
        for status in ((401,) if keyed else ()) + (422, *statuses)
    }
