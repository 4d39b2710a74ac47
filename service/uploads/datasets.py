"""The datasets resource: store an upload (dedupe, recognise, publish, record), list, delete.

The order of :func:`store_upload` makes a half-stored dataset impossible to see: the file is
moved into its folder, inspected there, and only then is the row committed; any failure
removes the folder. Two identical uploads racing each other end as one dataset (the unique
SHA-256 per project).

Nothing a client sends is dropped without a word. Identical bytes uploaded again *merge*: the
request's tags are added to the existing dataset (a schedule selecting by tag finds it) and
the dataset keeps its name; the answer's ``upload`` report says which tags were added and
which name was kept. A name or tag over its limit is refused (422 naming the field and the
limit), never cut; a file name is sanitised for storage and the report says how.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from pydantic import ValidationError
from sqlalchemy import ColumnElement, cast, column, exists, func, literal, select
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.exc import IntegrityError

from service.blobs.base import sanitize_filename
from service.db import ACTIVE_STATUSES, Dataset, Evaluation, get_owned, new_id
from service.errors import ConflictError, InvalidFieldsError, UploadError
from service.runtime import Runtime
from service.schemas.evaluations import MAX_TAGS, DatasetFields, UploadPublic
from service.uploads.multipart import ReceivedFile, ReceivedForm
from service.uploads.recordings import inspect_remote_upload, inspect_upload

__all__ = [
    "check_fields",
    "delete_dataset",
    "list_datasets",
    "parse_tags",
    "store_form",
    "store_upload",
]

_BAG_SUFFIXES: Final = {
    b"#ROSBAG": ".bag",
    b"\x89MCAP": ".mcap",
    b"SQLite format 3\x00": ".db3",
    b"PK\x03\x04": ".zip",
}
_MERGE_ATTEMPTS: Final = 5
_KINDS: Final = {".bag": "a ROS 1 bag", ".mcap": "an MCAP file", ".db3": "a ROS 2 SQLite bag"}


def parse_tags(text: str | None) -> list[str]:
    """Split ``"site-a, level 2"`` into tags (trimmed, unique, in order).

    Raises:
        InvalidFieldsError: too many tags, one too long, or one with control
            characters (each error names ``tags`` and the limit).
    """
    tags = list(dict.fromkeys(t.strip() for t in (text or "").split(",") if t.strip()))
    return _fields(tags=tags).tags


def check_fields(*, name: str | None, tags: list[str]) -> DatasetFields:
    """Check a dataset's name and tags against their limits before its bytes arrive.

    Raises:
        InvalidFieldsError: a name or tag over its limit (422 naming the field).
    """
    return _fields(name=name, tags=tags)


def _fields(**values: object) -> DatasetFields:
    """Check the upload's text fields against their limits (422 naming the field)."""
    try:
        return DatasetFields.model_validate(values)
    except ValidationError as err:
        raise InvalidFieldsError(errors=err.errors()) from None


def _shown(text: str, limit: int = 80) -> str:
    """Return a client's text quoted for a note, shortened when it is long."""
    return repr(text if len(text) <= limit else text[: limit - 3] + "...")


def _filename(received: ReceivedFile) -> tuple[str, list[str]]:
    """Return the stored file name of an upload and the notes on how it differs from the sent."""
    sent = received.filename or received.field
    name, changes = sanitize_filename(sent)
    notes = [f"The file name {_shown(sent)} is stored as {name!r}: {'; '.join(changes)}."]
    if not received.filename:
        notes = [f"The file came without a name; it is stored as {name!r}."]
    elif not changes:
        notes = []
    head = received.incoming.head
    for magic, suffix in _BAG_SUFFIXES.items():
        if head.startswith(magic) and not name.lower().endswith(suffix):
            what = _KINDS.get(suffix, "a zip archive")
            notes.append(f"The suffix {suffix!r} was added to the file name: it is {what}.")
            return name + suffix, notes  # the bag readers tell storage formats by suffix
    return name, notes


def _merge_tags(runtime: Runtime, dataset_id: str, tags: list[str]) -> tuple[Dataset, list[str]]:
    """Add the tags a dataset lacks; return it and the tags this call added.

    The row is locked where the database can (PostgreSQL); the check is repeated after
    each write, so two requests merging at once both end with their tags present.

    Raises:
        InvalidFieldsError: the merged tags would be more than a dataset holds.
    """
    added: list[str] = []
    for _ in range(_MERGE_ATTEMPTS):
        with runtime.sessions() as session:
            dataset = session.get_one(Dataset, dataset_id, with_for_update=True)
            missing = [t for t in tags if t not in dataset.tags]
            if not missing:
                session.expunge(dataset)
                return dataset, added
            if len(dataset.tags) + len(missing) > MAX_TAGS:
                msg = (
                    f"these bytes are dataset {dataset.name!r} already, with "
                    f"{len(dataset.tags)} tags; adding {len(missing)} would pass the limit "
                    f"of {MAX_TAGS} tags per dataset"
                )
                error = {"loc": ("tags",), "msg": msg, "type": "too_long", "input": tags}
                raise InvalidFieldsError(errors=[error])
            dataset.tags = [*dataset.tags, *missing]
            session.commit()
            added.extend(t for t in missing if t not in added)
    msg = "The tags could not be merged (the dataset changed repeatedly); send them again."
    raise ConflictError(msg)


def _existing(
    runtime: Runtime, existing: Dataset, *, name: str | None, tags: list[str], filename: str
) -> tuple[Dataset, UploadPublic]:
    """Answer an upload of bytes the project has: merge the tags, keep the name, say so."""
    dataset, added = _merge_tags(runtime, existing.id, tags)
    notes = [
        (
            f"These bytes were uploaded before as {dataset.filename!r}: this is that dataset "
            "(identical bytes are stored once per project)."
        )
    ]
    name_kept = None
    if name is not None and name != dataset.name:
        name_kept = dataset.name
        notes.append(
            f"The dataset keeps its name {dataset.name!r}; the name {_shown(name)} of this "
            "request was not applied."
        )
    elif filename != dataset.filename:
        notes.append(f"The file name {filename!r} of this request was not applied.")
    if added:
        notes.append(f"Tags added to the dataset: {', '.join(added)}.")
    report = UploadPublic(deduplicated=True, tags_added=added, name_kept=name_kept, notes=notes)
    return dataset, report


def store_upload(
    runtime: Runtime,
    project_id: str,
    received: ReceivedFile,
    *,
    name: str | None = None,
    tags: list[str] | None = None,
) -> tuple[Dataset, UploadPublic]:
    """Store an upload as a dataset of the project, or find the identical one.

    Identical bytes are stored once per project: the existing dataset is returned with
    this request's tags merged into its own and its name kept; the report says so.

    Returns:
        The dataset and the report of what became of the request (``deduplicated`` when
        the dataset existed).

    Raises:
        ReaderError: the file is not a recording loceval can read (nothing is kept).
        InvalidFieldsError: the name or the tags are over their limits.
    """
    fields = _fields(name=name, tags=tags or [])
    tags = fields.tags
    filename, notes = _filename(received)
    with runtime.sessions() as session:
        existing = session.scalar(
            select(Dataset).where(
                Dataset.project_id == project_id, Dataset.sha256 == received.sha256
            )
        )
    if existing is not None:
        received.incoming.abort()
        return _existing(runtime, existing, name=fields.name, tags=tags, filename=filename)
    dataset_id = new_id()
    with runtime.store.publishing(dataset_id):  # a sweep removes the folder if we die inside
        return _publish(
            runtime, project_id, received, dataset_id, fields=fields, notes=notes, filename=filename
        )


def _publish(
    runtime: Runtime,
    project_id: str,
    received: ReceivedFile,
    dataset_id: str,
    *,
    fields: DatasetFields,
    notes: list[str],
    filename: str,
) -> tuple[Dataset, UploadPublic]:
    """Move a new upload into its folder, inspect it there and record its row."""
    relative = runtime.store.publish_upload(
        received.incoming,
        project_id=project_id,
        dataset_id=dataset_id,
        filename=filename,
        sha256=received.sha256,
    )
    try:  # its errors name the stored path: problem_for() scrubs the server's folders
        remote = runtime.store.remote_file(relative, filename=filename)
        if remote is not None:  # a bag in a bucket: read by ranges where it lies, never copied
            if received.held is not None:  # its tf and poses, kept as it streamed in
                from loceval.readers.rosbag import HeldFile  # noqa: PLC0415  (rosbags)

                remote = HeldFile(remote, received.held)
            inspection = inspect_remote_upload(remote, filename)
        else:
            with runtime.store.pinned():
                local = runtime.store.local_path(
                    relative, filename=filename, sha256=received.sha256
                )
                inspection = inspect_upload(local, filename)
    except BaseException:
        runtime.store.remove_upload(dataset_id, relative)
        raise
    dataset = Dataset(
        id=dataset_id,
        project_id=project_id,
        name=fields.name or filename,
        filename=filename,
        kind=str(inspection["kind"]),
        size_bytes=received.size,
        sha256=received.sha256,
        tags=fields.tags,
        inspection=inspection,
        storage_path=relative,
    )
    with runtime.sessions() as session:
        try:
            session.add(dataset)
            session.commit()
        except IntegrityError:
            session.rollback()
            winner = session.scalar(
                select(Dataset).where(
                    Dataset.project_id == project_id, Dataset.sha256 == received.sha256
                )
            )
            if winner is None or winner.storage_path != relative:  # content-addressed: shared
                runtime.store.remove_upload(dataset_id, relative)
            if winner is None:
                raise
            return _existing(runtime, winner, name=fields.name, tags=fields.tags, filename=filename)
        except BaseException:
            runtime.store.remove_upload(dataset_id, relative)
            raise
    report = UploadPublic(deduplicated=False, tags_added=fields.tags, notes=notes)
    return dataset, report


def store_form(
    runtime: Runtime, project_id: str, form: ReceivedForm
) -> tuple[Dataset, UploadPublic]:
    """Store the file of a ``POST /datasets`` form with its name and tags.

    Returns:
        The dataset and the report of what became of the request.

    Raises:
        UploadError: the form has no file, or a single-valued field twice.
        InvalidFieldsError: the name or the tags are over their limits.
        ReaderError: the file is not a recording loceval can read (nothing is kept).
    """
    name = form.value("name")
    tags = parse_tags(",".join(form.values("tags")))
    if not form.files:
        msg = "The upload has no file; send it in the multipart field 'file'."
        raise UploadError(msg)
    return store_upload(runtime, project_id, form.files[0], name=name, tags=tags)


def _has_tag(tag: str, dialect: str) -> ColumnElement[bool]:
    """Return the SQL condition "the dataset's tags (a JSON list) hold ``tag``"."""
    if dialect == "postgresql":
        return cast(Dataset.tags, JSONB).contains([tag])
    values = func.json_each(Dataset.tags).table_valued("value")
    return exists(select(literal(1)).select_from(values).where(column("value") == tag))


def list_datasets(
    runtime: Runtime,
    project_id: str,
    *,
    tag: str | None,
    limit: int,
    offset: int,
    sha256: str | None = None,
) -> tuple[Sequence[Dataset], int]:
    """Return a page of the project's datasets, newest first, and how many there are.

    ``sha256`` keeps the dataset holding those bytes (at most one per project): a client
    asks whether the service holds a file before uploading it.
    """
    where: list[ColumnElement[bool]] = [Dataset.project_id == project_id]
    if tag is not None:
        where.append(_has_tag(tag, runtime.engine.dialect.name))
    if sha256 is not None:
        where.append(Dataset.sha256 == sha256.lower())
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
    runtime.store.remove_upload(dataset.id, dataset.storage_path)
