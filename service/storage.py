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

__all__ = ["BlobStore", "safe_filename"]

_UNSAFE: Final = re.compile(r"[^\w.\-+]+")
_ID_FOLDER: Final = re.compile(
    r"(?:datasets|evaluations|runs)/[0-9a-f-]{36}/(?:\.staging-[0-9a-f]+/|artifacts/)?"
)


def safe_filename(name: str, *, default: str = "upload") -> str:
    """Return a file name safe to store: no folders, no control or shell characters.

    The suffix is kept (readers sniff ``.mcap``, ``.bag``, ``.zip`` by it).
    """
    base = name.replace("\\", "/").rsplit("/", 1)[-1]
    base = unicodedata.normalize("NFKC", base).strip().lstrip(".")
    base = _UNSAFE.sub("_", base)[-200:]
    return base or default


class BlobStore:
    """The data directory's files."""

    def __init__(self, root: Path) -> None:
        """Use (and create) the folders under ``root``."""
        self.root = root.resolve()
        self.incoming = self.root / "incoming"
        self.datasets = self.root / "datasets"
        self.evaluations = self.root / "evaluations"
        self.runs = self.root / "runs"
        for folder in (self.incoming, self.datasets, self.evaluations, self.runs):
            folder.mkdir(parents=True, exist_ok=True)

    def scrub(self, message: str) -> str:
        """Remove the server's folders from a message for a client, keeping file names."""
        return _ID_FOLDER.sub("", message.replace(f"{self.root}/", ""))

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

    def artifacts_dir(self, evaluation_id: str) -> Path:
        """Return the folder of an evaluation's artifacts (present once it succeeded)."""
        return self.evaluations / evaluation_id / "artifacts"

    def staging_dir(self, evaluation_id: str) -> Path:
        """Return a fresh folder to write an evaluation's artifacts into."""
        return _new_staging(self.evaluations / evaluation_id)

    def publish_artifacts(self, evaluation_id: str, staging: Path) -> Path:
        """Rename a finished staging folder into place, replacing an earlier attempt's."""
        return _publish(staging, self.artifacts_dir(evaluation_id))

    def run_artifacts_dir(self, run_id: str) -> Path:
        """Return the folder of a schedule run's summary report."""
        return self.runs / run_id / "artifacts"

    def run_staging_dir(self, run_id: str) -> Path:
        """Return a fresh folder to write a schedule run's report into."""
        return _new_staging(self.runs / run_id)

    def publish_run_artifacts(self, run_id: str, staging: Path) -> Path:
        """Rename a run's finished staging folder into place."""
        return _publish(staging, self.run_artifacts_dir(run_id))

    def remove_run(self, run_id: str) -> None:
        """Delete a schedule run's files."""
        shutil.rmtree(self.runs / run_id, ignore_errors=True)

    def clear_evaluation(self, evaluation_id: str) -> None:
        """Remove an evaluation's staging leftovers and artifacts (before a new attempt)."""
        folder = self.evaluations / evaluation_id
        if folder.exists():
            for child in folder.iterdir():
                shutil.rmtree(child, ignore_errors=True)

    def remove_evaluation(self, evaluation_id: str) -> None:
        """Delete everything of an evaluation."""
        shutil.rmtree(self.evaluations / evaluation_id, ignore_errors=True)

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
