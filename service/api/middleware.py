"""Authenticate ``/api/v1`` requests before anything reads their body.

FastAPI decodes a JSON body before it solves dependencies, so without this a request with
no key but a malformed body would get 422 instead of 401 (and an upload would be parsed for
nobody). This ASGI middleware checks the key first and records the project on the request's
state; :func:`service.api.deps.current_project` then only reads it.

A path under ``/api/v1`` that matches no route at all (``/api/v1/healthz``) is passed on
without a key, so the app answers its 404 problem: asking for a key to reach nothing would
send the user after the wrong fix. A known route with an unknown id, or with a method it
does not answer to, still needs the key.

Once the key is known, a path or query holding a NUL character (``%00``) is refused with
422 here, for every route at once: no id, tag or filter is ever NUL-bearing, and PostgreSQL
cannot even compare text with one (it would fail the request with a 500). A query parameter
given twice (``?tag=a&tag=b``) is refused with 422 too: every one the API takes holds one
value, and FastAPI would silently keep the last, so the schema (one value) and the server
would not agree.

When the database cannot be reached, the key cannot be looked up: the answer is the 503
problem with ``Retry-After`` that every route gives in an outage (never a 500, and the
kept-alive connection stays usable), not a 401 that would send the user after a new key.
"""

from __future__ import annotations

import json
import logging
from collections import Counter
from typing import Any, Final
from urllib.parse import parse_qsl

import anyio.to_thread
from starlette.routing import Match
from starlette.types import ASGIApp, Receive, Scope, Send

from service.adapters import converted
from service.auth import authenticate
from service.errors import (
    PROBLEM_JSON,
    AuthenticationError,
    ServiceUnavailableError,
    problem,
    problem_for,
    problem_headers,
)
from service.logs import log_context
from service.runtime import Runtime

__all__ = ["PROJECT_STATE_KEY", "ApiKeyMiddleware"]

logger = logging.getLogger(__name__)

PROJECT_STATE_KEY: Final = "project_id"
_PREFIX: Final = "/api/v1"
_MISSING: Final = (
    "This endpoint needs an API key: send the header 'Authorization: Bearer KEY' "
    "(loceval keys create --project NAME prints one)."
)
_UNKNOWN: Final = "The API key is unknown or revoked; ask your administrator for a new one."


class ApiKeyMiddleware:
    """Answer 401 (problem+json) to ``/api/v1`` requests without an active key."""

    def __init__(self, app: ASGIApp) -> None:
        """Wrap the application."""
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check the key of API requests; pass everything else through."""
        path = str(scope.get("path", ""))
        if scope["type"] != "http" or not (path == _PREFIX or path.startswith(_PREFIX + "/")):
            await self.app(scope, receive, send)
            return
        if not _routed(scope):  # nothing there: the app answers 404, no key needed
            await self.app(scope, receive, send)
            return
        key = _bearer(scope)
        runtime: Runtime = scope["app"].state.runtime
        project_id = None
        if key is not None:
            try:
                project_id = await anyio.to_thread.run_sync(_lookup, runtime, key)
            except ServiceUnavailableError as err:
                logger.error("%s: %s", type(err).__name__, err)  # noqa: TRY400  (no traceback)
                headers = [
                    (k.lower().encode(), v.encode()) for k, v in problem_headers(err).items()
                ]
                await _send_problem(send, problem_for(err, private=runtime.private_roots), headers)
                return
        if project_id is None:
            await _refuse(send, _MISSING if key is None else _UNKNOWN)
            return
        if nul := _nul_locations(scope):
            await _send_problem(send, _nul_problem(nul))
            return
        if repeated := _repeated_names(scope):
            await _send_problem(send, _repeated_problem(repeated))
            return
        scope.setdefault("state", {})[PROJECT_STATE_KEY] = project_id
        with log_context(project=project_id):
            await self.app(scope, receive, send)


def _routed(scope: Scope) -> bool:
    """Return whether any route of the app matches the request's path (any method)."""
    routes = scope["app"].router.routes
    return any(route.matches(scope)[0] is not Match.NONE for route in routes)


def _bearer(scope: Scope) -> str | None:
    headers: list[tuple[bytes, bytes]] = scope.get("headers", [])
    for name, value in headers:
        if name == b"authorization":
            scheme, _, credentials = value.decode("latin-1").partition(" ")
            if scheme.lower() == "bearer" and credentials.strip():
                return credentials.strip()
            return None
    return None


def _lookup(runtime: Runtime, key: str) -> str | None:
    with converted("database"), runtime.sessions() as session:
        project_id: str | None = authenticate(session, key)
        return project_id


def _nul_locations(scope: Scope) -> list[list[str]]:
    """Return where the path or the query holds a NUL character (``loc`` lists)."""
    found = [["path"]] if "\x00" in str(scope.get("path", "")) else []
    query = bytes(scope.get("query_string", b"")).decode("latin-1")
    if "%00" in query or "\x00" in query:
        pairs = parse_qsl(query, keep_blank_values=True)
        found += [["query", name] for name, value in pairs if "\x00" in name + value]
    return found


def _repeated_names(scope: Scope) -> list[str]:
    """Return the query parameters given more than once (every one the API takes is single)."""
    query = bytes(scope.get("query_string", b"")).decode("latin-1")
    counts = Counter(name for name, _ in parse_qsl(query, keep_blank_values=True))
    return sorted(name for name, count in counts.items() if count > 1)


def _repeated_problem(names: list[str]) -> dict[str, Any]:
    msg = "is given more than once; give it once"
    errors = [{"loc": ["query", name], "msg": msg, "type": "repeated_parameter"} for name in names]
    where = "; ".join(f"query.{name}: {msg}" for name in names)
    detail = f"The request is not valid: {where}."
    return problem(422, "request.invalid", "RequestValidationError", detail, errors=errors)


def _nul_problem(locations: list[list[str]]) -> dict[str, Any]:
    msg = "holds a NUL character (%00); remove it"
    errors = [{"loc": loc, "msg": msg, "type": "nul_character"} for loc in locations]
    where = "; ".join(f"{'.'.join(loc)}: {msg}" for loc in locations)
    detail = f"The request is not valid: {where}."
    return problem(422, "request.invalid", "RequestValidationError", detail, errors=errors)


async def _refuse(send: Send, detail: str) -> None:
    error = AuthenticationError(detail)
    headers = [(k.lower().encode(), v.encode()) for k, v in problem_headers(error).items()]
    await _send_problem(send, problem_for(error), headers)


async def _send_problem(
    send: Send, document: dict[str, Any], headers: list[tuple[bytes, bytes]] | None = None
) -> None:
    body = json.dumps(document).encode("utf-8")
    await send(
        {
            "type": "http.response.start",
            "status": int(document["status"]),
            "headers": [
                (b"content-type", PROBLEM_JSON.encode()),
                (b"content-length", str(len(body)).encode()),
                *(headers or []),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})
