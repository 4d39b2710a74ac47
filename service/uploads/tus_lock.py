"""One writer per resumable upload, across threads, processes and replicas; gone with its holder.

With PostgreSQL a session advisory lock on a connection of its own (apart from the runtime's
pool, so uploads in progress never take the connections the requests need); else a ``flock``
on a file in the data folder. Both die with the process that holds them.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Final

from sqlalchemy import Engine, create_engine, text
from sqlalchemy.engine import Connection
from sqlalchemy.pool import NullPool

from service.errors import UploadLockedError
from service.runtime import Runtime

__all__ = ["WAIT_S", "UploadLock", "lock_path", "locked"]

WAIT_S: Final = 5.0
"""How long a request waits for another one's lock on the upload, seconds."""

_lock_engines: dict[str, Engine] = {}
"""An engine per database whose connections hold the uploads' advisory locks."""
_lock_engines_lock = threading.Lock()


class UploadLock:
    """One writer per upload, across threads, processes and replicas; gone with its holder."""

    def __init__(self, runtime: Runtime, upload_id: str) -> None:
        """Make the lock of ``upload_id`` (not yet taken: :meth:`acquire`)."""
        self.runtime = runtime
        self.upload_id = upload_id
        self._connection: Connection | None = None
        self._fd: int | None = None
        self._postgres = runtime.engine.dialect.name == "postgresql"
        digest = hashlib.sha256(upload_id.encode()).digest()
        self._key = int.from_bytes(digest[:8], "big", signed=True)
        self.path = lock_path(runtime, upload_id)

    def acquire(self, wait_s: float = WAIT_S) -> bool:
        """Take the lock, waiting up to ``wait_s``; return whether it was taken."""
        deadline = time.monotonic() + wait_s
        while not self._try():
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.05)
        return True

    def _try(self) -> bool:
        if self._postgres:
            if self._connection is None:
                self._connection = _lock_engine(self.runtime.engine).connect()
            taken = bool(
                self._connection.scalar(text("SELECT pg_try_advisory_lock(:k)"), {"k": self._key})
            )
            self._connection.commit()
            return taken
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return False
        try:
            same = os.fstat(fd).st_ino == self.path.stat().st_ino
        except FileNotFoundError:
            same = False
        if not same:  # deleted (the upload ended) between the open and the lock
            os.close(fd)
            return self._try()
        self._fd = fd
        return True

    def release(self, *, remove: bool = False) -> None:
        """Let go of the lock (``remove``: the upload is gone, its lock file goes too)."""
        if self._connection is not None:
            try:
                self._connection.execute(text("SELECT pg_advisory_unlock(:k)"), {"k": self._key})
                self._connection.commit()
            except Exception:  # noqa: BLE001  (a broken connection: the server let the lock go)
                self._connection.invalidate()
            self._connection.close()
            self._connection = None
        if self._fd is not None:
            if remove:
                self.path.unlink(missing_ok=True)
            os.close(self._fd)
            self._fd = None


def _lock_engine(engine: Engine) -> Engine:
    """Return the engine of the advisory locks on ``engine``'s database (one connection each)."""
    url = engine.url.render_as_string(hide_password=False)
    with _lock_engines_lock:
        if url not in _lock_engines:
            _lock_engines[url] = create_engine(url, poolclass=NullPool)
        return _lock_engines[url]


def lock_path(runtime: Runtime, upload_id: str) -> Path:
    """Return the lock file of an upload (without PostgreSQL)."""
    return runtime.store.root / "tus" / f"{upload_id}.lock"


@contextlib.contextmanager
def locked(runtime: Runtime, upload_id: str, wait_s: float = WAIT_S) -> Iterator[UploadLock]:
    """Hold the upload's lock for the block.

    Raises:
        UploadLockedError: another request held it for all of ``wait_s`` (423).
    """
    lock = UploadLock(runtime, upload_id)
    if not lock.acquire(wait_s):
        lock.release()
        msg = (
            "Another request is writing to this upload at the moment; ask its offset again "
            "(HEAD) in a moment and continue from there."
        )
        raise UploadLockedError(msg)
    try:
        yield lock
    finally:
        lock.release()
