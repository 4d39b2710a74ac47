"""Move a data folder's uploads and artifacts into a bucket (``loceval storage migrate``).

For a team that outgrows one machine: with the service stopped, the command copies every
dataset's file to its content-addressed key (checking its SHA-256 against the database) and
points the row at it, and copies every evaluation's and schedule run's artifacts to their
keys. Each dataset is committed on its own, so an interrupted run is continued by running the
command again (rows already in the bucket are skipped, artifacts already there with the same
size too). The local folder is left as it was: delete its ``datasets/``, ``evaluations/`` and
``runs/`` once the service runs from the bucket.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Protocol

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from service.blobs.base import EVALUATIONS, RUNS, Blobs
from service.blobs.s3 import S3Blobs, store_errors
from service.db import Dataset

__all__ = ["MigrationCounts", "migrate_folder"]

logger = logging.getLogger(__name__)

_HASH_CHUNK: Final = 8 << 20


class _Opened(Protocol):
    """What a migration needs of a process's runtime: the database and the store."""

    @property
    def sessions(self) -> sessionmaker[Session]:
        """The metadata database's session factory."""
        ...

    @property
    def store(self) -> Blobs:
        """The blob store to copy into."""
        ...


@dataclass
class MigrationCounts:
    """What a migration did.

    Attributes:
        datasets: dataset files copied (rows now pointing into the bucket).
        already: datasets that were in the bucket before.
        missing: datasets whose file was not in the folder (left as they are), as
            ``(id, path)``.
        artifacts: artifact files copied.
        bytes: bytes copied.
    """

    datasets: int = 0
    already: int = 0
    missing: list[tuple[str, str]] | None = None
    artifacts: int = 0
    bytes: int = 0


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        while chunk := fh.read(_HASH_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def migrate_folder(
    runtime: _Opened, source: Path, *, say: Callable[[str], None] = lambda _line: None
) -> MigrationCounts:
    """Copy the uploads and artifacts of the data folder ``source`` into the runtime's bucket.

    Args:
        runtime: a runtime whose store is a bucket (``LOCEVAL_BLOB_URL=s3://...``) and whose
            database is the one the folder's service used.
        source: the data folder to copy from.
        say: receives one line per copied dataset.

    Raises:
        ValueError: the runtime's store is not a bucket, or a file's SHA-256 is not the one
            recorded when it was uploaded (the file changed on disk: nothing of it is copied).
        StoreUnavailableError: the bucket cannot be reached.
    """
    store = runtime.store
    if not isinstance(store, S3Blobs):
        msg = "Set LOCEVAL_BLOB_URL=s3://BUCKET[/PREFIX] to the bucket to move the data into."
        raise ValueError(msg)  # noqa: TRY004  (a setting, reported as a bad input)
    counts = MigrationCounts(missing=[])
    with runtime.sessions() as session:
        rows = session.execute(
            select(Dataset.id, Dataset.project_id, Dataset.sha256, Dataset.storage_path)
        ).all()
    for dataset_id, project_id, sha256, storage_path in rows:
        key = f"datasets/{project_id}/{sha256}"
        if storage_path == key:
            counts.already += 1
            continue
        path = source / storage_path
        if not path.is_file():
            assert counts.missing is not None  # noqa: S101
            counts.missing.append((str(dataset_id), str(storage_path)))
            continue
        if _sha256(path) != sha256:
            msg = (
                f"{storage_path} does not hold the bytes uploaded as dataset {dataset_id} "
                "(its SHA-256 differs); restore the file or delete the dataset, then run again."
            )
            raise ValueError(msg)
        if not store.exists(key):
            with store_errors():
                store.client.upload_file(str(path), store.bucket, store.prefix + key)
        with runtime.sessions() as session:
            session.get_one(Dataset, dataset_id).storage_path = key
            session.commit()
        counts.datasets += 1
        counts.bytes += path.stat().st_size
        say(f"dataset {dataset_id}: {storage_path} -> {key}")
    for folder in (EVALUATIONS, RUNS):
        counts.artifacts += _copy_artifacts(store, source / folder, folder, counts)
    return counts


def _copy_artifacts(store: S3Blobs, local: Path, folder: str, counts: MigrationCounts) -> int:
    """Copy ``local/<id>/artifacts/*`` to ``<folder>/<id>/artifacts/*``; return how many."""
    copied = 0
    if not local.is_dir():
        return 0
    for path in sorted(local.glob("*/artifacts/*")):
        if not path.is_file():
            continue
        key = f"{folder}/{path.relative_to(local).as_posix()}"
        if store.size(key) == path.stat().st_size:
            continue
        with store_errors():
            store.client.upload_file(str(path), store.bucket, store.prefix + key)
        copied += 1
        counts.bytes += path.stat().st_size
    return copied
