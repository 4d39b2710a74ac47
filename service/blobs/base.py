"""The blob store interface: what the service asks of the place its files live.

Two backends implement it: :class:`service.blobs.local.LocalBlobs` (the data directory, the
embedded default) and :class:`service.blobs.s3.S3Blobs` (an S3-compatible bucket, chosen by
``LOCEVAL_BLOB_URL=s3://bucket/prefix``). Blobs are named by *keys*, paths relative to the
store's root with ``/`` separators (``datasets/...``, ``evaluations/<id>/artifacts/<name>``);
a dataset's key is its row's ``storage_path``.

A store never speaks HTTP: a download is handed out as what to send (:data:`Download`: a local
file, a presigned URL or a stream) and the routes make the response.

Readers and exporters work on local files, so the interface hands out local paths where they
need them: :meth:`Blobs.local_path` for an input (the file itself, or a copy in a bounded
cache keyed by content hash), :meth:`Blobs.job_staging_dir` for the artifacts being written
(published whole by :meth:`Blobs.publish_job_artifacts`).
"""

from __future__ import annotations

import abc
import contextlib
import re
import unicodedata
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final
from urllib.parse import quote

if TYPE_CHECKING:
    from loceval.readers.rosbag import HeldMessages, RemoteFile

__all__ = [
    "EVALUATIONS",
    "HEAD_BYTES",
    "MAX_FILENAME_BYTES",
    "RUNS",
    "STALE_UPLOAD_S",
    "Blobs",
    "Download",
    "Incoming",
    "LocalFile",
    "Redirect",
    "Stream",
    "Swept",
    "artifact_key",
    "content_disposition",
    "download_filename",
    "safe_filename",
    "sanitize_filename",
]

STALE_UPLOAD_S: Final = 3600.0
"""An upload untouched this long was abandoned (its sender is gone)."""

HEAD_BYTES: Final = 64
"""How many leading bytes of an upload are kept for sniffing its kind."""

EVALUATIONS: Final = "evaluations"
"""The folder of evaluation jobs."""
RUNS: Final = "runs"
"""The folder of schedule runs."""

_UNSAFE: Final = re.compile(r"[^\w.\-+]+")
_NOT_TOKEN: Final = re.compile(r"[^A-Za-z0-9.\-+_]+")
_SUFFIX: Final = re.compile(r"\.[0-9A-Za-z]{1,10}$")
MAX_FILENAME_BYTES: Final = 120
"""The longest stored file name, in UTF-8 bytes (file systems allow 255)."""


@dataclass(frozen=True, slots=True)
class Swept:
    """What one sweep of leftovers removed.

    Attributes:
        partial_uploads: uploads whose process is gone (or untouched for the grace period).
        datasets: dataset folders published by a process that died before recording them.
    """

    partial_uploads: int = 0
    datasets: int = 0


def sanitize_filename(name: str, *, default: str = "upload") -> tuple[str, list[str]]:
    r"""Return a file name safe to store and show, and what was changed, in words.

    The client's name is text, never a path: folders (``/`` and ``\``) are dropped, then
    everything but letters, digits, ``.``, ``-``, ``+`` and ``_`` (control characters,
    spaces, shell characters) becomes ``_``, leading dots go, and a name longer than
    :data:`MAX_FILENAME_BYTES` is shortened before its suffix (readers sniff ``.mcap``,
    ``.bag``, ``.zip`` by it). The result is never empty, ``.`` or ``..``.

    Args:
        name: the name the client gave.
        default: the name when nothing usable is left.

    Returns:
        The name, and one phrase per kind of change (empty when it is kept as sent).
    """
    changes: list[str] = []
    base = name.replace("\\", "/").rsplit("/", 1)[-1]
    if base != name:
        changes.append("its folders were removed")
    cleaned = _UNSAFE.sub("_", unicodedata.normalize("NFKC", base).strip().lstrip("."))
    if cleaned != base:
        changes.append(
            "characters other than letters, digits, '.', '-', '+' and '_' were replaced, "
            "leading dots removed"
        )
    fitted = _fit(cleaned, MAX_FILENAME_BYTES)
    if fitted != cleaned:
        changes.append(f"it was shortened to {MAX_FILENAME_BYTES} bytes")
    if not fitted.strip("._"):
        return default, [*changes, f"nothing usable was left, so it is {default!r}"]
    return fitted, changes


def safe_filename(name: str, *, default: str = "upload") -> str:
    """Return a file name safe to store: no folders, no control or shell characters.

    The suffix is kept (readers sniff ``.mcap``, ``.bag``, ``.zip`` by it); see
    :func:`sanitize_filename`.
    """
    return sanitize_filename(name, default=default)[0]


def _fit(name: str, max_bytes: int) -> str:
    """Shorten a name to ``max_bytes`` of UTF-8, cutting the stem and keeping the suffix."""
    if len(name.encode("utf-8")) <= max_bytes:
        return name
    match = _SUFFIX.search(name)
    suffix = match.group() if match else ""
    stem = name[: len(name) - len(suffix)].encode("utf-8")[: max_bytes - len(suffix)]
    return stem.decode("utf-8", "ignore") + suffix


def download_filename(stem: str, artifact: str, *, default: str) -> str:
    """Return the name a download is saved under: ``<stem>-<artifact>``.

    Two evaluations' ``report.pdf`` saved into one folder must not take each other's name,
    so the file is named after what it came from (``fr2_desk_ORB-report.pdf``).

    Args:
        stem: what the file came from, in words (an evaluation's estimates, a schedule); made
            safe like an upload's name (:func:`safe_filename`), letters of every script kept.
        artifact: the artifact's own name (``report.pdf``).
        default: the stem when nothing usable is left of ``stem`` (an id).
    """
    room = MAX_FILENAME_BYTES - len(artifact.encode("utf-8")) - 1
    safe = _fit(safe_filename(stem.replace(" ", "_"), default=default), room).strip("._-")
    return f"{safe or default}-{artifact}"


def content_disposition(filename: str, *, inline: bool) -> str:
    """Return the ``Content-Disposition`` of a download saved as ``filename`` (RFC 6266).

    ``filename=`` carries an ASCII form of the name (accents dropped, other characters
    ``_``); a name that is not ASCII adds it as ``filename*=UTF-8''...`` (RFC 8187), which
    browsers prefer. The value is ASCII, so a presigned URL can ask the bucket for it too.

    Args:
        filename: the name, as :func:`download_filename` made it (no quotes, no folders).
        inline: shown in the browser rather than saved.
    """
    kind = "inline" if inline else "attachment"
    plain = unicodedata.normalize("NFKD", filename).encode("ascii", "ignore").decode("ascii")
    plain = _NOT_TOKEN.sub("_", plain) or "download"
    if plain == filename:
        return f'{kind}; filename="{plain}"'
    return f"{kind}; filename=\"{plain}\"; filename*=UTF-8''{quote(filename, safe='')}"


@dataclass(frozen=True, slots=True)
class LocalFile:
    """A download served from a file on this machine.

    Attributes:
        path: the file.
    """

    path: Path


@dataclass(frozen=True, slots=True)
class Redirect:
    """A download the client fetches from the store itself (a presigned URL, 307).

    Attributes:
        url: where to fetch it; the store answers with the media type and disposition asked.
    """

    url: str


@dataclass(frozen=True, slots=True)
class Stream:
    """A download passed through from the store, chunk by chunk.

    Attributes:
        chunks: the bytes, in order.
        size: their total length.
    """

    chunks: Iterator[bytes]
    size: int


Download = LocalFile | Redirect | Stream
"""What a store hands out for a download (:meth:`Blobs.download`); the routes make the
response (:func:`service.api.downloads.download_response`)."""


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
        self.held: HeldMessages | None = None
        """An MCAP upload's small messages (tf, poses), kept as it streamed past (set by the
        receiver once the bytes are complete): a bucket stores them beside the object, so an
        evaluation reads them in one request (a folder's files are read locally: unused)."""

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
    private_roots: tuple[Path, ...] = ()
    """The server folders no message to a client may show (the data directory): the
    runtime's (:attr:`service.runtime.Runtime.private_roots`), scrubbed from every problem."""
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
    def download(self, key: str, *, media_type: str, filename: str, inline: bool) -> Download:
        """Return what to send for a download of a blob: a local file, a redirect or a stream.

        Args:
            key: the blob.
            media_type: its media type (a redirect's store answers with it).
            filename: the name the client saves it under.
            inline: shown in the browser rather than saved.
        """

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
