"""A loopback TCP proxy that counts what it forwards and cuts connections on cue.

:class:`CuttingProxy` listens on a free loopback port and forwards every connection to a
target port (which may change between connections: a restarted server, another replica).
It counts the bytes sent towards the target (what the server received) and, once that count
reaches each of the given thresholds, forwards exactly up to it and closes the connection on
both sides, as a dropped Wi-Fi link would. With ``stay_down`` the network then stays away
(every new connection is closed at once) until :meth:`allow`; with ``bytes_per_s`` the way
towards the target is a slow uplink (a site's Wi-Fi), so a browser's upload can be caught
midway. Plain threads, no dependency.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterable
from typing import Self

__all__ = ["CuttingProxy"]

_CHUNK = 64 * 1024
_SLOW_CHUNK = 16 * 1024


class CuttingProxy:
    """Forward ``127.0.0.1:port`` to ``127.0.0.1:target``; cut at the upstream byte counts given.

    Attributes:
        port: where clients connect.
        target: the port connections are forwarded to (set it to move new connections).
        sent: bytes forwarded towards the target so far.
        cuts: the counts at which a connection was cut.
    """

    def __init__(
        self,
        target: int,
        cut_at: Iterable[int] = (),
        *,
        stay_down: bool = False,
        bytes_per_s: float | None = None,
    ) -> None:
        """Listen on a free port (call :meth:`start` to serve)."""
        self.target = target
        self.stay_down = stay_down
        self.bytes_per_s = bytes_per_s
        self._down = False
        self.sent = 0
        self.cuts: list[int] = []
        self._pending = sorted(cut_at)
        self._lock = threading.Lock()
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port: int = self._listener.getsockname()[1]
        self._open: set[socket.socket] = set()
        self._closed = threading.Event()

    def cut_at(self, counts: Iterable[int]) -> None:
        """Cut the connection when the bytes sent towards the target reach each count."""
        with self._lock:
            self._pending = sorted(counts)

    @property
    def url(self) -> str:
        """The proxy's address."""
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> Self:
        """Serve in a background thread."""
        threading.Thread(target=self._accept, daemon=True, name="proxy-accept").start()
        return self

    def close(self) -> None:
        """Stop listening and drop every connection."""
        self._closed.set()
        with contextlib.suppress(OSError):
            self._listener.close()
        with self._lock:
            sockets = list(self._open)
        for sock in sockets:
            _drop(sock)

    def allow(self) -> None:
        """Forward new connections again (after a cut with ``stay_down``)."""
        with self._lock:
            self._down = False

    def cut_all(self) -> None:
        """Drop every open connection now (the network went away)."""
        with self._lock:
            sockets = list(self._open)
        for sock in sockets:
            _drop(sock)

    def __enter__(self) -> Self:
        """Serve for the ``with`` block."""
        return self.start()

    def __exit__(self, *exc: object) -> None:
        """Stop."""
        self.close()

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            with self._lock:
                down = self._down
            if down:
                _drop(client)  # the network is away: the client sees its connection closed
                continue
            try:
                upstream = socket.create_connection(("127.0.0.1", self.target), timeout=10)
            except OSError:
                _drop(client)  # the server is down: the client sees a refused connection
                continue
            upstream.settimeout(None)
            with self._lock:
                self._open.update({client, upstream})
            pair = (client, upstream)
            threading.Thread(target=self._pump_up, args=pair, daemon=True).start()
            threading.Thread(target=self._pump_down, args=pair, daemon=True).start()

    def _pump_up(self, client: socket.socket, upstream: socket.socket) -> None:
        """Client to server, counted, cut at the thresholds (slowly with ``bytes_per_s``)."""
        rate = self.bytes_per_s
        try:
            while data := client.recv(_SLOW_CHUNK if rate else _CHUNK):
                with self._lock:
                    limit = self._pending[0] - self.sent if self._pending else None
                    if limit is not None and len(data) >= limit:
                        data = data[:limit]
                        self.cuts.append(self._pending.pop(0))
                        self._down = self._down or self.stay_down
                        cut = True
                    else:
                        cut = False
                    self.sent += len(data)
                upstream.sendall(data)
                if cut:
                    break
                if rate:
                    time.sleep(len(data) / rate)
        except OSError:
            pass
        self._end(client, upstream)

    def _pump_down(self, client: socket.socket, upstream: socket.socket) -> None:
        """Server to client, as it comes."""
        try:
            while data := upstream.recv(_CHUNK):
                client.sendall(data)
        except OSError:
            pass
        self._end(client, upstream)

    def _end(self, client: socket.socket, upstream: socket.socket) -> None:
        with self._lock:
            self._open.difference_update({client, upstream})
        _drop(upstream)
        _drop(client)


def _drop(sock: socket.socket) -> None:
    """Close a socket at once (what was sent before stays sent)."""
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)
    with contextlib.suppress(OSError):
        sock.close()
