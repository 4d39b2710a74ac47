"""Turn a received upload into a dataset: dedupe, recognise, publish, record.

The order makes a half-stored dataset impossible to see: the file is moved into its folder,
inspected there, and only then is the row committed; any failure removes the folder. Two
identical uploads racing each other end as one dataset (the unique SHA-256 per project).
"""

from __future__ import annotations

from typing import Final

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from loceval.errors import InputError, LocevalError
from service.db import Dataset, new_id
from service.jobs import Runtime
from service.recordings import inspect_upload
from service.storage import safe_filename
from service.uploads import ReceivedFile

__all__ = ["parse_tags", "store_upload"]

_BAG_SUFFIXES: Final = {
    b"#ROSBAG": ".bag",
    b"\x89MCAP": ".mcap",
    b"SQLite format 3\x00": ".db3",
    b"PK\x03\x04": ".zip",
}
_MAX_TAGS: Final = 20


def parse_tags(text: str | None) -> list[str]:
    """Split ``"site-a, level 2"`` into tags (trimmed, unique, in order).

    Raises:
        InputError: too many tags or one too long.
    """
    tags = list(dict.fromkeys(t.strip() for t in (text or "").split(",") if t.strip()))
    if len(tags) > _MAX_TAGS or any(len(t) > 50 for t in tags):
        msg = f"Give at most {_MAX_TAGS} tags of up to 50 characters, separated by commas."
        raise InputError(msg)
    return tags


def _filename(received: ReceivedFile) -> str:
    name = safe_filename(received.filename or received.field)
    with received.path.open("rb") as fh:
        head = fh.read(16)
    for magic, suffix in _BAG_SUFFIXES.items():
        if head.startswith(magic) and not name.lower().endswith(suffix):
            return name + suffix  # the bag readers tell storage formats by suffix
    return name


def store_upload(
    runtime: Runtime,
    project_id: str,
    received: ReceivedFile,
    *,
    name: str | None = None,
    tags: list[str] | None = None,
) -> tuple[Dataset, bool]:
    """Store an upload as a dataset of the project, or find the identical one.

    Returns:
        The dataset and whether it is new.

    Raises:
        ReaderError: the file is not a recording loceval can read (nothing is kept).
    """
    with runtime.sessions() as session:
        existing = session.scalar(
            select(Dataset).where(
                Dataset.project_id == project_id, Dataset.sha256 == received.sha256
            )
        )
    if existing is not None:
        received.path.unlink(missing_ok=True)
        return existing, False
    filename = _filename(received)
    dataset_id = new_id()
    relative = runtime.store.publish_dataset(received.path, dataset_id, filename)
    try:
        inspection = inspect_upload(runtime.store.path(relative), filename)
    except LocevalError as err:
        runtime.store.remove_dataset(dataset_id)
        raise type(err)(runtime.store.scrub(str(err))) from err
    except BaseException:
        runtime.store.remove_dataset(dataset_id)
        raise
    dataset = Dataset(
        id=dataset_id,
        project_id=project_id,
        name=(name or filename)[:300],
        filename=filename,
        kind=str(inspection["kind"]),
        size_bytes=received.size,
        sha256=received.sha256,
        tags=tags or [],
        inspection=inspection,
        storage_path=relative,
    )
    with runtime.sessions() as session:
        try:
            session.add(dataset)
            session.commit()
        except IntegrityError:
            session.rollback()
            runtime.store.remove_dataset(dataset_id)
            winner = session.scalar(
                select(Dataset).where(
                    Dataset.project_id == project_id, Dataset.sha256 == received.sha256
                )
            )
            if winner is None:
                raise
            return winner, False
        except BaseException:
            runtime.store.remove_dataset(dataset_id)
            raise
    return dataset, True
