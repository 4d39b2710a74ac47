"""The blob store interface: what the service asks of the place its files live.

Two backends implement it: :class:`service.blobs.local.LocalBlobs` (the data directory, the
embedded default) and :class:`service.blobs.s3.S3Blobs` (an S3-compatible bucket, chosen by
``LOCEVAL_BLOB_URL=s3://bucket/prefix``). Blobs are named by *keys*, paths relative to the
store's root with ``/`` separators (``datasets/...``, ``evaluations/<id>/artifacts/<name>``);
a dataset's key is its row's ``storage_path``.

Readers and exporters work on local files, so the interface hands out local paths where they
need them: :meth:`Blobs.local_path` for an input (the file itself, or a copy in a bounded
cache keyed by content hash), :meth:`Blobs.job_staging_dir` for the artifacts being written
(published whole by :meth:`Blobs.publish_job_artifacts`).
"""

from __future__ import annotations

import abc
import contextlib
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Final

from starlette.responses import Response

from service.blobs.storage import Swept

if TYPE_CHECKING:
    from loceval.readers.rosbag import RemoteFile

__all__ = [
    "HEAD_BYTES",
    "STALE_UPLOAD_S",
    "Blobs",
    "Incoming",
    "artifact_key",
]

STALE_UPLOAD_S: Final = 3600.0
"""An upload untouched this long was abandoned (its sender is gone)."""

HEAD_BYTES: Final = 64
"""How many leading bytes of an upload are kept for sniffing its kind."""


def artifact_key(folder: str, job_id: str, name: str) -> str:
    """Return the key of a job's artifact (``evaluations/<id>/artifacts/report.pdf``)."""
    return f"{folder}/{job_id}/artifacts/{name}"


class Incoming(abc.ABC):
    """An upload being received: written in order, then committed whole or aborted.

    Nothing of it is visible under a dataset's key until :meth:`Blobs.publish_dataset`;
    :meth:`abort` removes whatever was received (and is a no-op once published).
    """

    def __init__(self) -> None:
        """Start with nothing received."""
        self.head = b""
        """The first :data:`HEAD_BYTES` bytes (a bag's magic)."""

    def write(self, chunk: bytes) -> None:
        """Append ``chunk``."""
        if len(self.head) < HEAD_BYTES:
            self.head += chunk[: HEAD_BYTES - len(self.head)]
        self._write(chunk)

    @abc.abstractmethod
    def _write(self, chunk: bytes) -> None:
        """Append ``chunk`` to the backend's copy."""

    @abc.abstractmethod
    def commit(self) -> None:
        """Make the received bytes durable (still not visible as a dataset)."""

    @abc.abstractmethod
    def abort(self) -> None:
        """Delete what was received; safe to call twice and after publishing."""


class Blobs(abc.ABC):
    """Uploads, inputs and artifacts of the service, wherever they live.

    Attributes:
        root: the local data directory (the SQLite files, the input cache, staging folders).
        kind: ``"local"`` or ``"s3"`` (in logs and metrics).
    """

    root: Path
    kind: str
    reads_in_place: bool = False
    """Whether bags are read where they lie (:meth:`remote_file`), not from a local copy."""

    @property
    @abc.abstractmethod
    def description(self) -> str:
        """Where the blobs are, for the start-up line (no credentials)."""

    # -- uploads ---------------------------------------------------------------------------

    @abc.abstractmethod
    def open_incoming(self) -> Incoming:
        """Start receiving an upload."""

    @abc.abstractmethod
    def publish_upload(
        self, incoming: Incoming, *, project_id: str, dataset_id: str, filename: str, sha256: str
    ) -> str:
        """Move a committed upload into place; return its key (the dataset's storage path).

        Identical bytes of one project get one key where the backend addresses content
        (a second upload of them then only drops its received copy).
        """

    @abc.abstractmethod
    def remove_upload(self, dataset_id: str, storage_path: str) -> None:
        """Delete a dataset's file (its id's folder, or its key)."""

    def publishing(self, dataset_id: str) -> contextlib.AbstractContextManager[None]:
        """Mark a dataset as being published while inside (a sweep reads the mark).

        A local folder marks the dataset's folder; a bucket keeps the upload's pending
        marker until the block ends without an error (the row is recorded), so a sweep
        deletes an object whose process died before recording it.
        """
        del dataset_id
        return contextlib.nullcontext()

    def close(self) -> None:  # noqa: B027  (most stores hold nothing to let go)
        """Let go of what this process holds (a local folder: its owner's lock)."""

    def leave(self) -> None:  # noqa: B027  (a folder's uploads need no lease)
        """Stop vouching for this process's uploads (the app's shutdown; a bucket's lease goes).

        Receiving again later vouches again.
        """

    def free_bytes(self) -> int | None:
        """Return the free bytes where uploads are written (None: no local disk, a bucket)."""
        return None

    @abc.abstractmethod
    def check_free_space(self, min_free_bytes: int, *, incoming_bytes: int = 0) -> bool:
        """Return whether ``incoming_bytes`` more leave at least ``min_free_bytes`` free."""

    # -- inputs ----------------------------------------------------------------------------

    @abc.abstractmethod
    def local_path(self, storage_path: str, *, filename: str, sha256: str) -> Path:
        """Return a local file with a dataset's bytes (held while :meth:`pinned` is open)."""

    def remote_file(self, storage_path: str, *, filename: str) -> RemoteFile | None:
        """Return a dataset's file to read by position where it lies, or None (read a copy).

        A bucket serves MCAP files and ROS 1 bags so (their readers seek to an index and
        read parts); a local folder's files are local already.
        """
        del storage_path, filename
        return None

    def job_input(
        self, storage_path: str, *, filename: str, sha256: str, size: int
    ) -> RemoteFile | None:
        """Return a bag an evaluation reads where it lies, or None (read :meth:`local_path`).

        A bucket hands out a large, indexed MCAP file that this machine holds no copy of:
        an evaluation reads its index and the wanted topics' messages by ranged reads, for
        a camera bag a small part of the file, instead of waiting for a download of all of
        it. A local folder's files are local already.
        """
        del storage_path, filename, sha256, size
        return None

    def pinned(self) -> contextlib.AbstractContextManager[None]:
        """Keep the local copies :meth:`local_path` hands out in this block from eviction."""
        return contextlib.nullcontext()

    # -- job artifacts ---------------------------------------------------------------------

    @abc.abstractmethod
    def job_staging_dir(self, folder: str, job_id: str) -> Path:
        """Return a fresh local folder (not yet created) to write a job's artifacts into."""

    @abc.abstractmethod
    def publish_job_artifacts(self, folder: str, job_id: str, staging: Path) -> Path:
        """Publish a finished staging folder whole; return a local folder holding the files.

        The returned folder is ``staging`` itself when the files were copied elsewhere
        (the caller's clean-up removes it), else the published folder.
        """

    @abc.abstractmethod
    def publish_job_artifact(self, folder: str, job_id: str, name: str, path: Path) -> None:
        """Publish one finished artifact of a running job ahead of the whole folder.

        Downloads see it at once; :meth:`publish_job_artifacts` later replaces it with the
        same file of the finished set.
        """

    @abc.abstractmethod
    def clear_job(self, folder: str, job_id: str) -> None:
        """Remove a job's staging leftovers and artifacts (before a new attempt)."""

    @abc.abstractmethod
    def remove_job(self, folder: str, job_id: str) -> None:
        """Delete everything of a job."""

    @abc.abstractmethod
    def job_ids(self, folder: str) -> Mapping[str, float]:
        """Return the job ids with files in ``folder`` and when each was last written."""

    # -- reading back ----------------------------------------------------------------------

    @abc.abstractmethod
    def exists(self, key: str) -> bool:
        """Return whether a blob exists."""

    @abc.abstractmethod
    def read_bytes(self, key: str) -> bytes:
        """Return a (small) blob's bytes."""

    @abc.abstractmethod
    def response(self, key: str, *, media_type: str, filename: str, inline: bool) -> Response:
        """Return the HTTP response that downloads a blob (streamed, or a redirect)."""

    # -- upkeep ----------------------------------------------------------------------------

    @abc.abstractmethod
    def sweep(
        self,
        recorded: Callable[[list[str]], Iterable[str]] = lambda _ids: (),
        *,
        older_than_s: float = STALE_UPLOAD_S,
        startup: bool = False,
    ) -> Swept:
        """Delete uploads abandoned mid-transfer (by a crash); return what was removed.

        Args:
            recorded: returns which of the given dataset ids have a row (the database); a
                local folder removes the unrecorded datasets of publishers that are gone.
            older_than_s: an upload untouched this long is abandoned.
            startup: this is the API process's start: its own earlier uploads are all
                abandoned, whatever their age.
        """

    def cached_bytes(self) -> int:
        """Return the bytes of local copies of stored inputs (0: the store is local)."""
        return 0

    @abc.abstractmethod
    def ping(self) -> None:
        """Raise :class:`~service.errors.StoreUnavailableError` when the store does not answer."""
