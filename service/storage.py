"""Blobs on disk: uploads and evaluation artifacts under the data directory.

Layout (paths in the database are relative to the data directory)::

    incoming/<uuid>.part                 an upload being received (never referenced)
    datasets/<dataset id>/<file name>    a stored upload
    evaluations/<id>/artifacts/          the artifacts of a succeeded evaluation
    evaluations/<id>/.staging-<uuid>/    artifacts being written (renamed into place whole)
    runs/<run id>/artifacts/             the summary report of a schedule run (same scheme)

Everything becomes visible by a rename within one file system, so a reader sees a whole file
or nothing; leftovers of a crash are swept on start.
"""

from __future__ import annotations

import re
import shutil
import time
import unicodedata
import uuid
from pathlib import Path
from typing import Final

from service.errors import register_private_root

__all__ = [
    "EVALUATIONS",
    "MAX_FILENAME_BYTES",
    "RUNS",
    "BlobStore",
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
        for folder in (self.incoming, self.datasets, self.evaluations, self.runs):
            folder.mkdir(parents=True, exist_ok=True)
        register_private_root(self.root)  # problem documents never show it

    def path(self, relative: str) -> Path:
        """Return the absolute path of a stored blob."""
        return self.root / relative

    def new_incoming(self) -> Path:
        """Return a fresh path for an upload being received."""
        return self.incoming / f"{uuid.uuid4().hex}.part"

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

    def sweep(self, *, older_than_s: float = 3600.0) -> int:
        """Delete uploads abandoned mid-transfer (by a crash); return how many."""
        cutoff = time.time() - older_than_s
        removed = 0
        for part in self.incoming.glob("*.part"):
            try:
                if part.stat().st_mtime < cutoff:
                    part.unlink()
                    removed += 1
            except FileNotFoundError:
                continue
        return removed


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
