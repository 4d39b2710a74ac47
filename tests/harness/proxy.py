"""A loopback TCP proxy that cuts connections: a site's network dropping mid-upload.

:class:`CuttingProxy` forwards ``127.0.0.1:port`` to a server and counts the bytes sent
towards it; when that count first passes each of ``cuts`` (bytes), it closes the connection
that carried them, both ways, as a dropped Wi-Fi link would. ``refuse()`` makes it close every
new connection at once (the network stays gone; ``stay_down`` does so after the first cut);
``allow()`` lets them through again. ``bytes_per_s`` makes the way towards the server a slow
uplink (a site's Wi-Fi), so that a browser's upload can be caught midway.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator, Sequence
from types import TracebackType
from typing import Self

from tests.harness.ports import free_port

__all__ = ["CuttingProxy", "cutting_proxy"]

_BLOCK = 64 * 1024
_SLOW_BLOCK = 16 * 1024


class CuttingProxy:
    """Forward a free loopback port to ``127.0.0.1:target``, cutting at byte counts.

    ``target`` may be set after the proxy starts (a server told the proxy's address as its
    public one starts after it).
    """

    def __init__(
        self,
        target: int,
        cuts: Sequence[int] = (),
        *,
        stay_down: bool = False,
        bytes_per_s: float | None = None,
    ) -> None:
        self.target = target
        self.bytes_per_s = bytes_per_s  # a slow uplink: bytes towards the server per second
        self.stay_down = stay_down  # after a cut, refuse every connection until allow()
        self.port = free_port()
        self.cuts = sorted(cuts)
        self.sent = 0  # bytes forwarded towards the server, over all connections
        self.cut_at: list[int] = []  # the counts at which a connection was cut
        self._refusing = False
        self._lock = threading.Lock()
        self._listener = socket.create_server(("127.0.0.1", self.port))
        self._open: set[socket.socket] = set()
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """The proxy's address, ``http://127.0.0.1:PORT``."""
        return f"http://127.0.0.1:{self.port}"

    def refuse(self) -> None:
        """Close every open and every new connection (the network is gone)."""
        with self._lock:
            self._refusing = True
            for sock in list(self._open):
                _close(sock)

    def allow(self) -> None:
        """Forward new connections again."""
        with self._lock:
            self._refusing = False

    def close(self) -> None:
        """Stop listening and close every connection."""
        _close(self._listener)
        self.refuse()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, _t: type[BaseException] | None, _e: BaseException | None, _b: TracebackType | None
    ) -> None:
        self.close()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            with self._lock:
                refusing = self._refusing
            if refusing:
                _close(client)
                continue
            try:
                upstream = socket.create_connection(("127.0.0.1", self.target))
            except OSError:
                _close(client)
                continue
            with self._lock:
                self._open.update({client, upstream})
            threading.Thread(
                target=self._pipe, args=(client, upstream), kwargs={"counted": True}, daemon=True
            ).start()
            threading.Thread(
                target=self._pipe, args=(upstream, client), kwargs={"counted": False}, daemon=True
            ).start()

    def _pipe(self, source: socket.socket, sink: socket.socket, *, counted: bool) -> None:
        slow = counted and self.bytes_per_s is not None
        try:
            while block := source.recv(_SLOW_BLOCK if slow else _BLOCK):
                if counted and self._cut_due(len(block)):
                    break
                sink.sendall(block)
                if slow and self.bytes_per_s:
                    time.sleep(len(block) / self.bytes_per_s)
        except OSError:
            pass
        finally:
            with self._lock:
                self._open.discard(source)
                self._open.discard(sink)
            _close(source)
            _close(sink)

    def _cut_due(self, size: int) -> bool:
        """Count ``size`` bytes; whether the connection is to be cut before sending them."""
        with self._lock:
            if self.cuts and self.sent + size > self.cuts[0]:
                self.cut_at.append(self.cuts.pop(0))
                self._refusing = self._refusing or self.stay_down
                return True
            self.sent += size
            return False


def _close(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)
    with contextlib.suppress(OSError):
        sock.close()


@contextlib.contextmanager
def cutting_proxy(
    target: int,
    cuts: Sequence[int] = (),
    *,
    stay_down: bool = False,
    bytes_per_s: float | None = None,
) -> Iterator[CuttingProxy]:
    """Run a :class:`CuttingProxy` for the ``with`` block."""
    proxy = CuttingProxy(target, cuts, stay_down=stay_down, bytes_per_s=bytes_per_s)
    try:
        yield proxy
    finally:
        proxy.close()
