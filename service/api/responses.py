"""OpenAPI descriptions of the problem documents each route can answer with."""

from __future__ import annotations

from typing import Any

from service.errors import PROBLEM_JSON
from service.schemas.evaluations import Problem

__all__ = ["problems"]

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


def problems(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """Return the ``responses=`` entries of these statuses, as problem+json."""
    return {
        status: {
            "model": Problem,
            "description": _DESCRIPTIONS[status],
            "content": {PROBLEM_JSON: {"schema": {"$ref": "#/components/schemas/Problem"}}},
        }
        for status in (401, 422, *statuses)
    }
