"""Authenticate ``/api/v1`` requests before anything reads their body.

FastAPI decodes a JSON body before it solves dependencies, so without this a request with
no key but a malformed body would get 422 instead of 401 (and an upload would be parsed for
nobody). This ASGI middleware checks the key first and records the project on the request's
state; :func:`service.api.deps.current_project` then only reads it.

A path under ``/api/v1`` that matches no route at all (``/api/v1/healthz``) is passed on
without a key, so the app answers its 404 problem: asking for a key to reach nothing would
send the user after the wrong fix. A known route with an unknown id, or with a method it
does not answer to, still needs the key.
"""

from __future__ import annotations

import json
from typing import Final

import anyio.to_thread
from starlette.routing import Match
from starlette.types import ASGIApp, Receive, Scope, Send

from service.auth import authenticate
from service.errors import PROBLEM_JSON, AuthenticationError, problem_for
from service.logs import log_context
from service.runtime import Runtime

__all__ = ["PROJECT_STATE_KEY", "ApiKeyMiddleware"]

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
            project_id = await anyio.to_thread.run_sync(_lookup, runtime, key)
        if project_id is None:
            await _refuse(send, _MISSING if key is None else _UNKNOWN)
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
    with runtime.sessions() as session:
        project_id: str | None = authenticate(session, key)
        return project_id


async def _refuse(send: Send, detail: str) -> None:
    body = json.dumps(problem_for(AuthenticationError(detail))).encode("utf-8")
    await send(
        {
            "type": "http.response.start",
            "status": 401,
            "headers": [
                (b"content-type", PROBLEM_JSON.encode()),
                (b"content-length", str(len(body)).encode()),
                (b"www-authenticate", b"Bearer"),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})
