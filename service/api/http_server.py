"""The HTTP server of ``loceval serve``: uvicorn on h11, with a limit on a request's head.

uvicorn's default HTTP parser (httptools) reads a request's header lines without a limit: a
client could send megabytes of headers and the server would hold them. h11 stops at
``max_incomplete_event_size`` bytes of an unfinished request head; uvicorn then answers a
plain 400, so the protocol here answers what h11 means by it: ``431 Request Header Fields
Too Large``, as a problem document like every other error.
"""

from __future__ import annotations

import json
from typing import Any, Final

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from service.errors import PROBLEM_JSON, problem

__all__ = ["MAX_HEAD_BYTES", "HeadLimitedH11Protocol", "run"]

MAX_HEAD_BYTES: Final = 64 * 1024
"""The longest request line and header lines together, in bytes."""
_LINGER_S: Final = 2.0
"""How long a refused connection is read (and dropped) before it is closed."""


def _too_large() -> bytes:
    detail = (
        f"The request's header lines are longer than {MAX_HEAD_BYTES // 1024} KiB together; "
        "send fewer or shorter headers (an API request needs a few hundred bytes)."
    )
    document = problem(431, "request.headers_too_large", "RequestHeaderFieldsTooLarge", detail)
    return json.dumps(document).encode("utf-8")


class HeadLimitedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol, answering 431 (not 400) to a request head over the limit."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:  # noqa: ANN401  (uvicorn's)
        """Set up the protocol and note why h11 refuses a request, when it does."""
        super().__init__(*args, **kwargs)
        self._status_hint = 400
        self._draining = False
        receive = self.conn.next_event

        def next_event() -> Any:  # noqa: ANN401  (h11's event or sentinel)
            try:
                return receive()
            except h11.RemoteProtocolError as err:
                self._status_hint = err.error_status_hint
                raise

        self.conn.next_event = next_event  # type: ignore[method-assign]

    def send_400_response(self, msg: str) -> None:
        """Answer a refused request: 431 with a problem document for an oversize head."""
        if self._status_hint != 431:
            super().send_400_response(msg)
            return
        self.logger.warning("Refused a request whose header lines pass %d bytes", MAX_HEAD_BYTES)
        body = _too_large()
        headers = [
            (b"content-type", PROBLEM_JSON.encode()),
            (b"content-length", str(len(body)).encode()),
            (b"connection", b"close"),
        ]
        response = h11.Response(
            status_code=431, headers=headers, reason=b"Request Header Fields Too Large"
        )
        for event in (response, h11.Data(data=body), h11.EndOfMessage()):
            self.transport.write(self.conn.send(event) or b"")
        # Closing now, with the rest of the client's head unread, would reset the connection
        # (TCP RST) and the client could lose the answer: finish sending, read and drop what
        # still comes for a moment, then close (a "lingering close").
        self._draining = True
        if self.transport.can_write_eof():
            self.transport.write_eof()
        self.loop.call_later(_LINGER_S, self.transport.close)

    def data_received(self, data: bytes) -> None:
        """Read a request; after a refusal, drop what the client still sends."""
        if not self._draining:
            super().data_received(data)


def run(app: Any, *, host: str, port: int) -> None:  # noqa: ANN401  (an ASGI app)
    """Serve ``app`` until SIGINT or SIGTERM."""
    import uvicorn  # noqa: PLC0415

    uvicorn.run(
        app,
        host=host,
        port=port,
        http=HeadLimitedH11Protocol,
        h11_max_incomplete_event_size=MAX_HEAD_BYTES,
        log_level="info",
        access_log=False,
    )
