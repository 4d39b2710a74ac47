"""The local backend: the data directory's folders, one machine's or a folder every one mounts.

Layout (paths in the database are relative to the data directory)::

    incoming/<owner>.<uuid>.part         an upload being received (never referenced)
    owners/<owner>.lock                  held locked (flock) by the process <owner> while it lives
    owners/<owner>.<id>.publishing       dataset <id> is being inspected, not yet recorded
    datasets/<dataset id>/<file name>    a stored upload
    evaluations/<id>/artifacts/          the artifacts of a succeeded evaluation
    evaluations/<id>/.staging-<uuid>/    artifacts being written (renamed into place whole)
    runs/<run id>/artifacts/             the summary report of a schedule run (same scheme)

Everything becomes visible by a rename within one file system, so a reader sees a whole file
or nothing; leftovers of a crash are swept on start.

Each process that opens the store is an *owner*: it holds an exclusive ``flock`` on its
lock file for as long as it runs, and names its partial uploads and datasets being published
after itself. The kernel drops the lock when the process dies (``kill -9`` included; on NFS
the server does when the client goes), so a sweep that can take an owner's lock knows the
owner is gone and removes what it left (:meth:`LocalBlobs.sweep`), at once, whichever of the
processes sharing the folder runs it.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import shutil
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO, Final

from service.blobs.base import (
    EVALUATIONS,
    RUNS,
    STALE_UPLOAD_S,
    Blobs,
    Incoming,
    LocalFile,
    Swept,
    safe_filename,
)
from service.errors import InsufficientStorageError

__all__ = ["STORAGE_FULL", "LocalBlobs", "LocalIncoming", "disk_full_refused"]

_OWNED: Final = re.compile(r"([0-9a-f]{32})\.(.+)\.(part|publishing)")
_PUBLISHING: Final = ".publishing"

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
        with disk_full_refused():
            self._fh.write(chunk)

    def commit(self) -> None:
        """See :meth:`Incoming.commit`."""
        if self._fh is not None:
            with disk_full_refused():
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
def disk_full_refused() -> Iterator[None]:
    """Turn a write that failed for a full disk (ENOSPC, EDQUOT) into the 507 refusal."""
    try:
        yield
    except OSError as err:
        if err.errno in {errno.ENOSPC, errno.EDQUOT}:
            raise InsufficientStorageError(STORAGE_FULL) from None
        raise


def _hold_lock(path: Path) -> int:
    """Create ``path`` and hold an exclusive flock on it; return the descriptor.

    A sweep may take and delete a lock file between its creation and its locking here; the
    lock is then on a deleted file, so it is taken again on a fresh one.
    """
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            if os.fstat(fd).st_ino == path.stat().st_ino:
                return fd
        except FileNotFoundError:
            pass
        os.close(fd)


def _take_if_gone(path: Path) -> int | None:
    """Take the lock of an owner that is gone; return the descriptor, or None if it lives."""
    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


class LocalBlobs(Blobs):
    """The data directory's files (one machine, or a folder every machine mounts)."""

    kind = "local"

    def __init__(self, root: Path) -> None:
        """Use (and create) the folders under ``root``."""
        self.root = root.resolve()
        self.incoming = self.root / "incoming"
        self.datasets = self.root / "datasets"
        self.evaluations = self.root / EVALUATIONS
        self.runs = self.root / RUNS
        self.owners = self.root / "owners"
        for folder in (self.incoming, self.datasets, self.evaluations, self.runs, self.owners):
            folder.mkdir(parents=True, exist_ok=True)
        self.private_roots = (self.root,)  # problem documents never show it
        self.owner = uuid.uuid4().hex
        self._lock: int | None = _hold_lock(self._lock_path(self.owner))

    def _lock_path(self, owner: str) -> Path:
        return self.owners / f"{owner}.lock"

    def close(self) -> None:
        """Let go of this process's lock: a later sweep removes what it left."""
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None

    def path(self, relative: str) -> Path:
        """Return the absolute path of a stored blob."""
        return self.root / relative

    def new_incoming(self) -> Path:
        """Return a fresh path for an upload being received."""
        return self.incoming / f"{self.owner}.{uuid.uuid4().hex}.part"

    @contextlib.contextmanager
    def publishing(self, dataset_id: str) -> Iterator[None]:
        """Mark a dataset as being published by this process for the ``with`` block.

        Wrap the publish, the inspection and the recording of the row: a sweep removes the
        dataset's folder when this process dies inside the block and the row is missing.
        """
        marker = self.owners / f"{self.owner}.{dataset_id}{_PUBLISHING}"
        marker.touch()
        try:
            yield
        finally:
            marker.unlink(missing_ok=True)

    def publish_dataset(self, partial: Path, dataset_id: str, filename: str) -> str:
        """Move a received upload into place; return its path relative to the data dir."""
        folder = self.datasets / dataset_id
        folder.mkdir(parents=True, exist_ok=True)
        target = folder / safe_filename(filename)
        partial.replace(target)
        return str(target.relative_to(self.root))

    def remove_dataset(self, dataset_id: str) -> None:
        """Delete a dataset's files."""
        shutil.rmtree(self.datasets / dataset_id, ignore_errors=True)

    def job_folder(self, folder: str, job_id: str) -> Path:
        """Return a job's folder in ``folder`` (``evaluations``, ``runs``)."""
        return self.root / folder / job_id

    def job_artifacts_dir(self, folder: str, job_id: str) -> Path:
        """Return the folder of a job's artifacts (present once it succeeded)."""
        return self.job_folder(folder, job_id) / "artifacts"

    def job_staging_dir(self, folder: str, job_id: str) -> Path:
        """Return a fresh folder to write a job's artifacts into (not yet created)."""
        return _new_staging(self.job_folder(folder, job_id))

    def publish_job_artifacts(self, folder: str, job_id: str, staging: Path) -> Path:
        """Rename a job's finished staging folder into place, replacing an earlier attempt's."""
        return _publish(staging, self.job_artifacts_dir(folder, job_id))

    def publish_job_artifact(self, folder: str, job_id: str, name: str, path: Path) -> None:
        """Put one finished artifact of a running job into its artifacts folder at once.

        The file is hard-linked (copied across file systems) under a temporary name and
        renamed into place, so a download never sees half of it.
        """
        final = self.job_artifacts_dir(folder, job_id)
        final.mkdir(parents=True, exist_ok=True)
        partial = final / f".{name}.{uuid.uuid4().hex}"
        try:
            os.link(path, partial)
        except OSError:
            shutil.copyfile(path, partial)
        partial.replace(final / name)

    def clear_job(self, folder: str, job_id: str) -> None:
        """Remove a job's staging leftovers and artifacts (before a new attempt)."""
        parent = self.job_folder(folder, job_id)
        if parent.exists():
            for child in parent.iterdir():
                shutil.rmtree(child, ignore_errors=True)

    def remove_job(self, folder: str, job_id: str) -> None:
        """Delete everything of a job."""
        shutil.rmtree(self.job_folder(folder, job_id), ignore_errors=True)

    def artifacts_dir(self, evaluation_id: str) -> Path:
        """Return the folder of an evaluation's artifacts (present once it succeeded)."""
        return self.job_artifacts_dir(EVALUATIONS, evaluation_id)

    def run_artifacts_dir(self, run_id: str) -> Path:
        """Return the folder of a schedule run's summary report."""
        return self.job_artifacts_dir(RUNS, run_id)

    def remove_run(self, run_id: str) -> None:
        """Delete a schedule run's files."""
        self.remove_job(RUNS, run_id)

    def sweep(
        self,
        recorded: Callable[[list[str]], Iterable[str]] = lambda _ids: (),
        *,
        older_than_s: float = STALE_UPLOAD_S,
        startup: bool = False,
    ) -> Swept:
        """Remove what processes that are gone left behind; return the counts.

        The partial uploads and unrecorded datasets of an owner whose lock can be taken go at
        once; a partial upload untouched for ``older_than_s`` goes whoever owns it (an upload
        in progress writes all the time), as do the unowned ones of older versions.

        Args:
            recorded: returns which of the given dataset ids have a row (the database);
                the folders of the others are removed when their publisher is gone.
            older_than_s: the age after which any partial upload is abandoned.
            startup: not needed here: an owner's lock tells at once whether its process is
                gone (see :meth:`Blobs.sweep`).
        """
        del startup
        gone: dict[str, int] = {}
        try:
            for lock in self.owners.glob("*.lock"):
                owner = lock.name.removesuffix(".lock")
                if owner != self.owner and (fd := _take_if_gone(lock)) is not None:
                    gone[owner] = fd
            parts = self._sweep_parts(gone, time.time() - older_than_s)
            datasets = self._sweep_unpublished(gone, recorded)
            for owner in gone:
                self._lock_path(owner).unlink(missing_ok=True)
        finally:
            for fd in gone.values():
                os.close(fd)
        return Swept(partial_uploads=parts, datasets=datasets)

    def _sweep_parts(self, gone: dict[str, int], cutoff: float) -> int:
        """Delete the partial uploads of owners that are gone, and those not written since."""
        removed = 0
        for path in self.incoming.glob("*.part"):
            match = _OWNED.fullmatch(path.name)
            if (match is not None and self._gone(match.group(1), gone)) or _older(path, cutoff):
                path.unlink(missing_ok=True)
                removed += 1
        return removed

    def _sweep_unpublished(
        self, gone: dict[str, int], recorded: Callable[[list[str]], Iterable[str]]
    ) -> int:
        """Delete the dataset folders that owners that are gone published but never recorded."""
        unpublished: dict[str, Path] = {}
        for marker in self.owners.glob(f"*{_PUBLISHING}"):
            match = _OWNED.fullmatch(marker.name)
            if match is not None and self._gone(match.group(1), gone):
                unpublished[match.group(2)] = marker
        if not unpublished:
            return 0
        removed = 0
        rows = set(recorded(sorted(unpublished)))
        for dataset_id, marker in unpublished.items():
            if dataset_id not in rows and (self.datasets / dataset_id).exists():
                self.remove_dataset(dataset_id)
                removed += 1
            marker.unlink(missing_ok=True)
        return removed

    def _gone(self, owner: str, gone: dict[str, int]) -> bool:
        """Whether an owner is gone: its lock was taken now, or its lock file was deleted."""
        if owner == self.owner:
            return False
        return owner in gone or not self._lock_path(owner).exists()

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

    def download(self, key: str, *, media_type: str, filename: str, inline: bool) -> LocalFile:
        """See :meth:`Blobs.download`: the file itself."""
        del media_type, filename, inline  # the route's response names them
        return LocalFile(self.path(key))

    def ping(self) -> None:
        """See :meth:`Blobs.ping`."""
        return


def _older(path: Path, cutoff: float) -> bool:
    """Whether a file was last written before ``cutoff`` (False once it is gone)."""
    try:
        return path.stat().st_mtime < cutoff
    except FileNotFoundError:
        return False


def _new_staging(parent: Path) -> Path:
    """Return a fresh staging folder's path in ``parent`` (created), the folder not yet."""
    parent.mkdir(parents=True, exist_ok=True)
    return parent / f".staging-{uuid.uuid4().hex}"


def _publish(staging: Path, final: Path) -> Path:
    """Rename a staging folder to ``final``, replacing an earlier attempt's folder."""
    if final.exists():
        old = final.with_name(f".old-{uuid.uuid4().hex}")
        final.rename(old)
        shutil.rmtree(old, ignore_errors=True)
    staging.rename(final)
    return final
