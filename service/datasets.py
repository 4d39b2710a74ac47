"""The datasets resource: store an upload (dedupe, recognise, publish, record), list, delete.

The order of :func:`store_upload` makes a half-stored dataset impossible to see: the file is
moved into its folder, inspected there, and only then is the row committed; any failure
removes the folder. Two identical uploads racing each other end as one dataset (the unique
SHA-256 per project).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from sqlalchemy import ColumnElement, cast, column, exists, func, literal, select
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.exc import IntegrityError

from loceval.errors import InputError
from service.db import ACTIVE_STATUSES, Dataset, Evaluation, get_owned, new_id
from service.errors import ConflictError, UploadError
from service.recordings import inspect_upload
from service.runtime import Runtime
from service.storage import safe_filename
from service.uploads import ReceivedFile, ReceivedForm

__all__ = ["delete_dataset", "list_datasets", "parse_tags", "store_form", "store_upload"]

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
    try:  # its errors name the stored path: problem_for() scrubs the server's folders
        inspection = inspect_upload(runtime.store.path(relative), filename)
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


def store_form(runtime: Runtime, project_id: str, form: ReceivedForm) -> tuple[Dataset, bool]:
    """Store the file of a ``POST /datasets`` form with its name and tags.

    Returns:
        The dataset and whether it is new.

    Raises:
        UploadError: the form has no file.
        InputError: the tags are not usable.
        ReaderError: the file is not a recording loceval can read (nothing is kept).
    """
    if not form.files:
        msg = "The upload has no file; send it in the multipart field 'file'."
        raise UploadError(msg)
    tags = parse_tags(",".join(form.values("tags")))
    return store_upload(runtime, project_id, form.files[0], name=form.value("name"), tags=tags)


def _has_tag(tag: str, dialect: str) -> ColumnElement[bool]:
    """Return the SQL condition "the dataset's tags (a JSON list) hold ``tag``"."""
    if dialect == "postgresql":
        return cast(Dataset.tags, JSONB).contains([tag])
    values = func.json_each(Dataset.tags).table_valued("value")
    return exists(select(literal(1)).select_from(values).where(column("value") == tag))


def list_datasets(
    runtime: Runtime, project_id: str, *, tag: str | None, limit: int, offset: int
) -> tuple[Sequence[Dataset], int]:
    """Return a page of the project's datasets, newest first, and how many there are."""
    where: list[ColumnElement[bool]] = [Dataset.project_id == project_id]
    if tag is not None:
        where.append(_has_tag(tag, runtime.engine.dialect.name))
    with runtime.sessions() as session:
        count = session.scalar(select(func.count()).select_from(Dataset).where(*where))
        rows = session.scalars(
            select(Dataset)
            .where(*where)
            .order_by(Dataset.created_at.desc(), Dataset.id)
            .limit(limit)
            .offset(offset)
        ).all()
    return rows, int(count or 0)


def delete_dataset(runtime: Runtime, project_id: str, dataset_id: str) -> None:
    """Delete a dataset and its file; finished evaluations keep their results and artifacts.

    Raises:
        NotFoundError: no such dataset in the project.
        ConflictError: a queued or running evaluation uses it.
    """
    dataset = get_owned(runtime.sessions, Dataset, dataset_id, project_id)
    with runtime.sessions() as session:
        active = session.scalars(
            select(Evaluation.dataset_ids).where(
                Evaluation.project_id == project_id,
                Evaluation.status.in_(ACTIVE_STATUSES),
            )
        ).all()
        if any(dataset.id in ids for ids in active):
            msg = (
                f"Dataset {dataset.name!r} is used by an evaluation that has not finished; "
                "delete it when the evaluation is done."
            )
            raise ConflictError(msg)
        session.delete(session.get_one(Dataset, dataset.id))
        session.commit()
    runtime.store.remove_dataset(dataset.id)
