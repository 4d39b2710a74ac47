"""The local backend: the data directory's folders (:class:`service.blobs.storage.BlobStore`).

Its behaviour is the store's as it was before object storage: uploads land in
``incoming/<uuid>.part`` and are renamed into ``datasets/<id>/``, artifacts are staged
next to their final folder and renamed into place, downloads are files.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO

from starlette.responses import FileResponse, Response

from service.blobs.base import STALE_UPLOAD_S, Blobs, Incoming
from service.blobs.storage import BlobStore, Swept
from service.errors import InsufficientStorageError

__all__ = ["STORAGE_FULL", "LocalBlobs", "LocalIncoming"]

STORAGE_FULL = (
    "The server's storage is nearly full, so the upload was not accepted (nothing of it was "
    "kept); try again later, or ask the server's administrator to free space in the data "
    "directory (LOCEVAL_DATA_DIR): delete old evaluations or datasets, set "
    "LOCEVAL_RETENTION_DAYS, or give the volume more space."
)


class LocalIncoming(Incoming):
    """An upload written to ``incoming/<uuid>.part``, fsynced on commit."""

    def __init__(self, path: Path) -> None:
        """Create the file (it must not exist)."""
        super().__init__()
        self.path = path
        self._fh: IO[bytes] | None = path.open("xb")

    def _write(self, chunk: bytes) -> None:
        if self._fh is None:
            msg = "the upload was committed or aborted"
            raise RuntimeError(msg)
        with _disk_full_refused():
            self._fh.write(chunk)

    def commit(self) -> None:
        """See :meth:`Incoming.commit`."""
        if self._fh is not None:
            with _disk_full_refused():
                self._fh.flush()
                os.fsync(self._fh.fileno())
            self._fh.close()
            self._fh = None

    def abort(self) -> None:
        """See :meth:`Incoming.abort`."""
        if self._fh is not None:
            with contextlib.suppress(OSError):  # an unflushable buffer (a full disk): it goes
                self._fh.close()
            self._fh = None
        self.path.unlink(missing_ok=True)


@contextlib.contextmanager
def _disk_full_refused() -> Iterator[None]:
    """Turn a write that failed for a full disk (ENOSPC, EDQUOT) into the 507 refusal."""
    try:
        yield
    except OSError as err:
        if err.errno in {errno.ENOSPC, errno.EDQUOT}:
            raise InsufficientStorageError(STORAGE_FULL) from None
        raise


class LocalBlobs(BlobStore, Blobs):
    """The data directory's files (one machine, or a folder every machine mounts)."""

    kind = "local"

    @property
    def description(self) -> str:
        """See :meth:`Blobs.description`."""
        return f"data in {self.root}"

    def open_incoming(self) -> LocalIncoming:
        """See :meth:`Blobs.open_incoming`."""
        return LocalIncoming(self.new_incoming())

    def publish_upload(
        self, incoming: Incoming, *, project_id: str, dataset_id: str, filename: str, sha256: str
    ) -> str:
        """See :meth:`Blobs.publish_upload`."""
        del project_id, sha256  # the folder is the dataset's own
        if not isinstance(incoming, LocalIncoming):
            msg = f"a {type(incoming).__name__} cannot be published in a folder"
            raise TypeError(msg)
        return self.publish_dataset(incoming.path, dataset_id, filename)

    def remove_upload(self, dataset_id: str, storage_path: str) -> None:
        """See :meth:`Blobs.remove_upload`."""
        del storage_path
        self.remove_dataset(dataset_id)

    def free_bytes(self) -> int:
        """See :meth:`Blobs.free_bytes`."""
        return shutil.disk_usage(self.incoming).free

    def check_free_space(self, min_free_bytes: int, *, incoming_bytes: int = 0) -> bool:
        """See :meth:`Blobs.check_free_space`."""
        if min_free_bytes <= 0:
            return True
        return shutil.disk_usage(self.incoming).free - incoming_bytes >= min_free_bytes

    def local_path(self, storage_path: str, *, filename: str, sha256: str) -> Path:
        """See :meth:`Blobs.local_path`."""
        del filename, sha256
        return self.path(storage_path)

    def job_ids(self, folder: str) -> Mapping[str, float]:
        """See :meth:`Blobs.job_ids`."""
        found: dict[str, float] = {}
        for child in (self.root / folder).iterdir():
            with contextlib.suppress(FileNotFoundError):
                found[child.name] = child.stat().st_mtime
        return found

    def exists(self, key: str) -> bool:
        """See :meth:`Blobs.exists`."""
        return self.path(key).is_file()

    def read_bytes(self, key: str) -> bytes:
        """See :meth:`Blobs.read_bytes`."""
        return self.path(key).read_bytes()

    def response(self, key: str, *, media_type: str, filename: str, inline: bool) -> Response:
        """See :meth:`Blobs.response`."""
        return FileResponse(
            self.path(key),
            media_type=media_type,
            filename=filename,
            content_disposition_type="inline" if inline else "attachment",
        )

    def sweep(
        self,
        recorded: Callable[[list[str]], Iterable[str]] = lambda _ids: (),
        *,
        older_than_s: float = STALE_UPLOAD_S,
        startup: bool = False,
    ) -> Swept:
        """See :meth:`Blobs.sweep` (the owners' locks tell which processes are gone)."""
        del startup  # an owner's lock tells at once whether its process is gone
        return BlobStore.sweep(self, recorded, older_than_s=older_than_s)

    def ping(self) -> None:
        """See :meth:`Blobs.ping`."""
        return
