"""One log line per HTTP request, with the request id in the context of every line it writes."""

from __future__ import annotations

import logging
import re
import time
import uuid
from typing import Final

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.logs import log_context

__all__ = ["RequestLogMiddleware"]

logger = logging.getLogger("service.requests")

_REQUEST_ID: Final = re.compile(r"^[\w.:-]{1,64}$")


class RequestLogMiddleware:
    """Write one line per HTTP request: method, path, status, duration, request id, project.

    The request id is the client's ``X-Request-ID`` when it is short and plain, else a new
    one; it is sent back in ``X-Request-ID`` and is in the context of every line the request
    writes (a job run inside the request included).
    """

    def __init__(self, app: ASGIApp) -> None:
        """Wrap the application."""
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Time the request and log it when the response has been sent (or failed)."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request_id = _request_id(scope)
        status = 500
        started = time.perf_counter()

        async def send_with_id(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
                headers = [*message.get("headers", []), (b"x-request-id", request_id.encode())]
                message = {**message, "headers": headers}
            await send(message)

        with log_context(request_id=request_id):
            try:
                await self.app(scope, receive, send_with_id)
            finally:
                state = scope.get("state") or {}
                logger.info(
                    "%s %s %d",
                    scope.get("method", ""),
                    scope.get("path", ""),
                    status,
                    extra={
                        "event": "request",
                        "method": scope.get("method", ""),
                        "path": scope.get("path", ""),
                        "status": status,
                        "duration_ms": round((time.perf_counter() - started) * 1000, 1),
                        "project": state.get("project_id"),
                    },
                )


def _request_id(scope: Scope) -> str:
    headers: list[tuple[bytes, bytes]] = scope.get("headers", [])
    for name, value in headers:
        if name == b"x-request-id":
            given = value.decode("latin-1")
            if _REQUEST_ID.match(given):
                return given
    return uuid.uuid4().hex[:16]
