"""What one process knows of the resumable uploads it received: digests and held messages.

An upload's SHA-256 is computed as its bytes stream in, and into a bucket an MCAP file's tf
and pose messages are kept as they pass (:class:`loceval.readers.rosbag.McapScan`); both are
carried from one request of the upload to its next in this process. A process that did not
see an upload from its first byte (a restart, another replica) knows neither: the SHA-256
is then read back from the assembled file, and the held messages are not stored (the
bag's index is read instead).
"""

from __future__ import annotations

import hashlib
import threading
from typing import TYPE_CHECKING, Any

from service.errors import UploadChecksumError
from service.uploads.multipart import mcap_scan

if TYPE_CHECKING:
    from loceval.readers.rosbag import McapScan

__all__ = ["Hashes", "clear", "forget", "settled"]

_digests: dict[str, tuple[int, Any]] = {}
"""The SHA-256 of each upload this process received from its first byte: (offset, hash)."""
_scans: dict[str, tuple[int, McapScan]] = {}
"""The held messages of each upload into a bucket this process received from its first byte
(offset, scan), when no request carried a checksum (a scan cannot take bytes back)."""
_lock = threading.Lock()


class Hashes:
    """The digests of one request's bytes: the upload's SHA-256 (when known) and its checksum.

    Into a bucket it also carries the upload's :class:`~loceval.readers.rosbag.McapScan`
    (when this process saw every byte before and no checksum is asked: a body a checksum
    refuses would already be in the scan).
    """

    def __init__(
        self, upload_id: str, start: int, checksum: tuple[str, bytes] | None, *, scan: bool
    ) -> None:
        """Take up the upload at ``start``: what this process knows of it up to there.

        Args:
            upload_id: the upload.
            start: the request's offset.
            checksum: the ``Upload-Checksum`` (algorithm, digest), or None.
            scan: keep an MCAP file's small messages (the store reads files in place).
        """
        with _lock:
            known = _digests.get(upload_id)
            scanned = _scans.pop(upload_id, None)  # only this request may feed it now
        self.sha256 = known[1].copy() if known is not None and known[0] == start else None
        if start == 0:
            self.sha256 = hashlib.sha256()
        self.check = (
            None
            if checksum is None
            else hashlib.new(checksum[0], usedforsecurity=False)  # the client's choice
        )
        self.scan = scanned[1] if scanned is not None and scanned[0] == start else None
        if start == 0 and scan:
            self.scan = mcap_scan()
        if self.check is not None:
            self.scan = None

    def update(self, data: bytes) -> None:
        """Take the request's next bytes."""
        if self.sha256 is not None:
            self.sha256.update(data)
        if self.check is not None:
            self.check.update(data)
        if self.scan is not None:
            self.scan.feed(data)

    def verify(self, expected: tuple[str, bytes] | None) -> None:
        """Refuse a body that does not match its ``Upload-Checksum`` (460)."""
        if expected is None or self.check is None or self.check.digest() == expected[1]:
            return
        msg = (
            f"The request's bytes do not match its Upload-Checksum ({expected[0]}); "
            "nothing of it was kept: send them again from the same offset."
        )
        raise UploadChecksumError(msg)

    def keep(self, upload_id: str, offset: int) -> None:
        """Remember the upload's SHA-256 (and scan) up to ``offset`` for its next request."""
        with _lock:
            if self.sha256 is not None:
                _digests[upload_id] = (offset, self.sha256.copy())
            if self.scan is not None:
                _scans[upload_id] = (offset, self.scan)


def settled(upload_id: str) -> tuple[tuple[int, Any] | None, tuple[int, McapScan] | None]:
    """Take an upload's digest and scan, each with its offset (None: not known here)."""
    with _lock:
        return _digests.pop(upload_id, None), _scans.pop(upload_id, None)


def forget(upload_id: str) -> None:
    """Drop what this process knows of an upload (it was terminated or expired)."""
    with _lock:
        _digests.pop(upload_id, None)
        _scans.pop(upload_id, None)


def clear() -> None:
    """Forget every upload, as a restarted process has (the tests' other replica)."""
    with _lock:
        _digests.clear()
        _scans.clear()
