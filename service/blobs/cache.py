"""A local cache of stored inputs, bounded in size and keyed by content hash.

Readers take files (a ROS 1 bag's index, a zipped bag folder, an MCAP's summary are found by
seeking in a file), so a worker on an object-store deployment reads each dataset from a
local copy: ``<cache>/<sha256>/<file name>`` (the name keeps the suffix the readers sniff).
A copy is fetched once per machine and reused by every job that reads the same bytes; the
least recently used copies are deleted when the cache would pass its size.

A copy in use is *pinned*: its entry's lock file is held with a shared ``flock`` for the
duration of :meth:`InputCache.pinned`, and eviction only takes entries whose exclusive lock
it gets without waiting, so a job never loses its input mid-read (also across processes
sharing the folder).
"""

from __future__ import annotations

import contextlib
import contextvars
import fcntl
import logging
import os
import shutil
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Final

from service.errors import InsufficientStorageError

__all__ = ["InputCache"]

logger = logging.getLogger(__name__)

_LOCK: Final = ".lock"
_PINS: contextvars.ContextVar[list[IO[bytes]] | None] = contextvars.ContextVar(
    "loceval_cache_pins", default=None
)


class InputCache:
    """Local copies of stored blobs, at most ``max_bytes`` of them (unpinned ones evicted).

    Args:
        root: the cache folder (created).
        max_bytes: the size the copies may take together.
        min_free_bytes: free space the file system keeps; a copy that would eat into it
            is refused.
    """

    def __init__(self, root: Path, *, max_bytes: int, min_free_bytes: int) -> None:
        """Use (and create) the cache folder."""
        self.root = root
        self.max_bytes = max_bytes
        self.min_free_bytes = min_free_bytes
        root.mkdir(parents=True, exist_ok=True)

    @contextlib.contextmanager
    def pinned(self) -> Iterator[None]:
        """Hold every copy :meth:`fetch` returns in this block (in this thread)."""
        pins: list[IO[bytes]] = []
        token = _PINS.set(pins)
        try:
            yield
        finally:
            _PINS.reset(token)
            for lock in pins:
                lock.close()  # releases the shared lock

    def fetch(
        self, sha256: str, filename: str, size: int, download: Callable[[Path], None]
    ) -> Path:
        """Return the local copy of a blob, downloading it first when it is not here.

        Args:
            sha256: the blob's content hash (the entry's name).
            filename: the file name the copy gets (readers sniff its suffix).
            size: the blob's size in bytes.
            download: writes the blob to the path it is given.

        Raises:
            InsufficientStorageError: the copy does not fit (the cache's size or the
                disk's reserve); the message names the setting to raise.
        """
        entry = self.root / sha256
        entry.mkdir(parents=True, exist_ok=True)
        lock = (entry / _LOCK).open("a+b")
        target = entry / filename
        try:
            # Shared first: a copy that is here is read by many (this job may hold it already,
            # the reference and the estimate of one bag); evictors keep off meanwhile.
            fcntl.flock(lock, fcntl.LOCK_SH)
            if _whole(target, size):
                os.utime(target)  # recently used
            else:
                fcntl.flock(lock, fcntl.LOCK_EX)  # one download per entry
                if not _whole(target, size):  # another process may have fetched it meanwhile
                    self._make_room(size, keep=sha256)
                    partial = entry / f".part-{uuid.uuid4().hex}"
                    try:
                        download(partial)
                        partial.replace(target)
                    finally:
                        partial.unlink(missing_ok=True)
                fcntl.flock(lock, fcntl.LOCK_SH)  # pinned while the caller's block runs
        except BaseException:
            lock.close()
            raise
        pins = _PINS.get()
        if pins is None:
            lock.close()  # no pinned() block: the copy may go whenever room is needed
        else:
            pins.append(lock)
        return target

    def holds(self, sha256: str, filename: str, size: int) -> bool:
        """Return whether a whole copy of the blob is here now (it may be evicted later)."""
        return _whole(self.root / sha256 / filename, size)

    def size(self) -> int:
        """Return the bytes the copies take."""
        return sum(size for _, _, size in self._entries())

    def _entries(self) -> list[tuple[float, Path, int]]:
        """Return (last use, folder, bytes) of every entry."""
        found = []
        for entry in self.root.iterdir():
            with contextlib.suppress(FileNotFoundError):
                files = [f for f in entry.iterdir() if f.name != _LOCK]
                used = max((f.stat().st_mtime for f in files), default=0.0)
                found.append((used, entry, sum(f.stat().st_size for f in files)))
        return found

    def _make_room(self, size: int, *, keep: str) -> None:
        """Evict the least recently used unpinned copies until ``size`` more bytes fit."""
        if size > self.max_bytes:
            msg = (
                f"A dataset of {size / 1e9:.2f} GB does not fit the worker's input cache of "
                f"{self.max_bytes / 1e9:.2f} GB; raise LOCEVAL_BLOB_CACHE_BYTES on the workers."
            )
            raise InsufficientStorageError(msg)
        entries = sorted(self._entries())
        total = sum(bytes_ for _, _, bytes_ in entries)
        for _, entry, bytes_ in entries:
            if total + size <= self.max_bytes and self._disk_allows(size):
                break
            if entry.name != keep and _evict(entry):
                total -= bytes_
        if not self._disk_allows(size):
            msg = (
                f"The worker's disk has too little free space for a {size / 1e9:.2f} GB input "
                "(LOCEVAL_MIN_FREE_BYTES is kept free); give the worker's data folder more space."
            )
            raise InsufficientStorageError(msg)

    def _disk_allows(self, size: int) -> bool:
        return shutil.disk_usage(self.root).free - size >= self.min_free_bytes


def _whole(path: Path, size: int) -> bool:
    """Return whether ``path`` is a complete copy (``size`` bytes)."""
    try:
        return path.stat().st_size == size
    except FileNotFoundError:
        return False


def _evict(entry: Path) -> bool:
    """Delete a cache entry unless a job holds it; return whether it went."""
    try:
        lock = (entry / _LOCK).open("a+b")
    except FileNotFoundError:
        return False
    with lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False  # pinned by a running job
        for child in entry.iterdir():
            if child.name != _LOCK:
                child.unlink(missing_ok=True)
    logger.info("Evicted the cached input %s", entry.name)
    return True
