"""Blobs on disk: uploads and evaluation artifacts under the data directory.

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
owner is gone and removes what it left (:meth:`BlobStore.sweep`), at once, whichever of the
processes sharing the folder runs it.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import time
import unicodedata
import uuid
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from service.errors import register_private_root

__all__ = [
    "EVALUATIONS",
    "MAX_FILENAME_BYTES",
    "RUNS",
    "BlobStore",
    "Swept",
    "safe_filename",
    "sanitize_filename",
]

EVALUATIONS: Final = "evaluations"
"""The folder of evaluation jobs."""
RUNS: Final = "runs"
"""The folder of schedule runs."""

_UNSAFE: Final = re.compile(r"[^\w.\-+]+")
_SUFFIX: Final = re.compile(r"\.[0-9A-Za-z]{1,10}$")
MAX_FILENAME_BYTES: Final = 120
"""The longest stored file name, in UTF-8 bytes (file systems allow 255)."""
_OWNED: Final = re.compile(r"([0-9a-f]{32})\.(.+)\.(part|publishing)")
_PUBLISHING: Final = ".publishing"


@dataclass(frozen=True, slots=True)
class Swept:
    """What one sweep of leftovers removed.

    Attributes:
        partial_uploads: uploads whose process is gone (or untouched for the grace period).
        datasets: dataset folders published by a process that died before recording them.
    """

    partial_uploads: int = 0
    datasets: int = 0


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


class BlobStore:
    """The data directory's files."""

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
        register_private_root(self.root)  # problem documents never show it
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
        older_than_s: float = 3600.0,
    ) -> Swept:
        """Remove what processes that are gone left behind; return the counts.

        The partial uploads and unrecorded datasets of an owner whose lock can be taken go at
        once; a partial upload untouched for ``older_than_s`` goes whoever owns it (an upload
        in progress writes all the time), as do the unowned ones of older versions.

        Args:
            recorded: returns which of the given dataset ids have a row (the database);
                the folders of the others are removed when their publisher is gone.
            older_than_s: the age after which any partial upload is abandoned.
        """
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
