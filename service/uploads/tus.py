"""Resumable uploads: the tus 1.0 protocol without a web framework.

The protocol's core and its extensions creation, creation-with-upload, termination, checksum
and expiration.

An upload is created with its length and metadata (``filename``, the dataset's ``name``, its
``tags``), then receives its bytes in any number of requests, each starting at the offset
the database holds (:class:`service.db.TusUpload`); the bytes lie in the blob store
(:mod:`service.blobs.resumable`), so any API replica continues an upload another started, and
a restarted one continues its own. A request cut off midway keeps what arrived (unless it
carried a checksum, which only the whole body can match); a process killed midway keeps what
it had recorded (every part of 8 MiB). When the last byte arrives, the upload becomes a
dataset exactly as ``POST /datasets`` makes one (:func:`service.uploads.datasets.store_upload`:
inspection, deduplication by SHA-256, the ``upload`` notes).

One request writes to an upload at a time: a lock that dies with its holder (a PostgreSQL
advisory lock on its connection; else a ``flock`` in the data folder) guards it, and a second
writer is told 423 (tus clients try again). The SHA-256 is computed as the bytes stream in;
a process that did not see them all (a restart, another replica) reads the assembled file
once more to compute it. Into a bucket, an MCAP file's tf and pose messages are kept as they
stream in, as ``POST /datasets`` keeps them (:class:`loceval.readers.rosbag.McapScan`), and
stored beside the object, so an evaluation reads them in one request; an upload a process
did not see whole is stored without them (its evaluations read the bag's index instead).

Unfinished uploads expire ``upload_expiry_s`` after their last write: :func:`sweep_expired`
(every minute in the queue's consumers) removes their parts and aborts their multipart
uploads; finished ones are forgotten (their datasets stay).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import logging
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any, Final

import anyio
import anyio.to_thread
from sqlalchemy import select, update

from loceval.errors import LocevalError
from service.blobs.resumable import ResumableWriter, resumable_parts
from service.db import Dataset, TusUpload, new_id, utcnow
from service.errors import (
    NotFoundError,
    ServiceUnavailableError,
    UploadError,
    UploadLockedError,
    UploadMediaTypeError,
    UploadOffsetError,
    UploadTooLargeError,
    problem_for,
)
from service.runtime import Runtime
from service.uploads import datasets, tus_hashes
from service.uploads.multipart import ReceivedFile, check_free_space
from service.uploads.tus_hashes import Hashes
from service.uploads.tus_headers import (
    CHECKSUM_ALGORITHMS,
    EXTENSIONS,
    OFFSET_MEDIA_TYPE,
    TUS_VERSION,
    check_version,
    parse_checksum,
    parse_int,
    parse_metadata,
)
from service.uploads.tus_lock import UploadLock, locked

__all__ = [
    "CHECKSUM_ALGORITHMS",
    "EXTENSIONS",
    "OFFSET_MEDIA_TYPE",
    "TUS_VERSION",
    "Received",
    "check_version",
    "create_upload",
    "delete_upload",
    "find_upload",
    "receive",
    "settle",
    "sweep_expired",
]

logger = logging.getLogger(__name__)

_BATCH_BYTES: Final = 1 << 20
_SWEEP_BATCH: Final = 200


@dataclass(frozen=True, slots=True)
class Received:
    """Where an upload stands after a request wrote to it.

    Attributes:
        upload: the row (its ``offset`` is the new one).
        dataset_id: the dataset it became, once complete.
    """

    upload: TusUpload
    dataset_id: str | None


# -- expiry --------------------------------------------------------------------------------


def _expires(runtime: Runtime) -> dt.datetime:
    return utcnow() + dt.timedelta(seconds=runtime.settings.upload_expiry_s)


# -- rows ----------------------------------------------------------------------------------


def find_upload(runtime: Runtime, project_id: str, upload_id: str) -> TusUpload:
    """Return an upload of the project.

    Raises:
        NotFoundError: no such upload in this project (another project's too), or expired.
    """
    row = None
    if "\x00" not in upload_id and len(upload_id) <= 36:
        with runtime.sessions() as session:
            row = session.get(TusUpload, upload_id)
    if row is None or row.project_id != project_id:
        msg = (
            f"No upload {upload_id!r} in this project (unfinished uploads expire "
            f"{runtime.settings.upload_expiry_s / 3600:g} h after their last write); "
            "create a new one with POST /api/v1/uploads."
        )
        raise NotFoundError(msg)
    return row


def _record(
    runtime: Runtime, row: TusUpload, offset: int, state: dict[str, Any], **values: object
) -> None:
    """Record a new offset and state of an upload (the lock is held)."""
    expires = _expires(runtime)
    with runtime.sessions() as session:
        done = session.execute(
            update(TusUpload)
            .where(TusUpload.id == row.id, TusUpload.offset == row.offset)
            .values(offset=offset, state=state, expires_at=expires, **values)
        )
        session.commit()
    if not done.rowcount:  # type: ignore[attr-defined]
        msg = f"Upload {row.id!r} was deleted meanwhile; create a new one."
        raise NotFoundError(msg)
    row.offset, row.state, row.expires_at = offset, state, expires
    for name, value in values.items():
        setattr(row, name, value)


def create_upload(
    runtime: Runtime, project_id: str, *, length: str | None, metadata: str | None
) -> TusUpload:
    """Create an upload of ``length`` bytes with its metadata.

    Raises:
        UploadError: no ``Upload-Length`` (deferred lengths are not supported), malformed
            metadata.
        UploadTooLargeError: longer than ``max_upload_bytes`` (413).
        InvalidFieldsError: the name or the tags over their limits (422).
        InsufficientStorageError: the data folder would keep less than its reserve (507).
    """
    if length is None:
        msg = (
            "Send the upload's size in Upload-Length (this server does not support "
            "Upload-Defer-Length)."
        )
        raise UploadError(msg)
    size = parse_int(length, "Upload-Length")
    limit = runtime.settings.max_upload_bytes
    if size > limit:
        msg = (
            f"The upload's {size:,} bytes are more than the limit of {limit:,} bytes "
            "(Tus-Max-Size); split the recording, or raise LOCEVAL_MAX_UPLOAD_BYTES on the server."
        )
        raise UploadTooLargeError(msg)
    fields = parse_metadata(metadata)
    tags = datasets.parse_tags(fields.get("tags"))
    name = (fields.get("name") or "").strip() or None
    datasets.check_fields(name=name, tags=tags)
    check_free_space(runtime.store, runtime.settings.min_free_bytes, incoming_bytes=size)
    row = TusUpload(
        id=new_id(),
        project_id=project_id,
        length=size,
        offset=0,
        filename=fields.get("filename", ""),
        name=name,
        tags=tags,
        metadata_header=(metadata or "").strip(),
        state={},
        expires_at=_expires(runtime),
    )
    with runtime.sessions() as session:
        session.add(row)
        session.commit()
    state = resumable_parts(runtime.store, row.id).begin()
    with runtime.sessions() as session:
        session.execute(update(TusUpload).where(TusUpload.id == row.id).values(state=state))
        session.commit()
    row.state = state
    return row


def delete_upload(runtime: Runtime, project_id: str, upload_id: str) -> None:
    """Terminate an upload: its parts go (a finished upload's dataset stays).

    Raises:
        NotFoundError: no such upload in this project.
        UploadLockedError: a request is writing to it (423).
    """
    find_upload(runtime, project_id, upload_id)
    with locked(runtime, upload_id) as lock:
        row = find_upload(runtime, project_id, upload_id)
        _forget(runtime, row)
        lock.release(remove=True)
    logger.info("Upload %s terminated at %d of %d bytes", row.id, row.offset, row.length)


def _forget(runtime: Runtime, row: TusUpload) -> None:
    """Remove an upload's stored parts (unless they are a dataset now) and its row."""
    if row.dataset_id is None and not _published(runtime, row):
        resumable_parts(runtime.store, row.id).remove(row.state)
    with runtime.sessions() as session:
        obj = session.get(TusUpload, row.id)
        if obj is not None:
            session.delete(obj)
            session.commit()
    tus_hashes.forget(row.id)


def _published(runtime: Runtime, row: TusUpload) -> Dataset | None:
    """Return the dataset an assembled upload became before its row could say so (a crash)."""
    sha256 = row.state.get("sha256")
    if not sha256:
        return None
    with runtime.sessions() as session:
        dataset = session.scalar(
            select(Dataset).where(Dataset.project_id == row.project_id, Dataset.sha256 == sha256)
        )
    if dataset is None:
        return None
    parts = resumable_parts(runtime.store, row.id)
    return dataset if parts.became(row.state, dataset.storage_path) else None


# -- receiving -----------------------------------------------------------------------------


def _write(
    runtime: Runtime, row: TusUpload, writer: ResumableWriter, hashes: Hashes, data: bytes
) -> None:
    """Append a batch; record the durable progress unless a checksum must match first."""
    writer.write(data)
    hashes.update(data)
    if hashes.check is None:
        point = writer.checkpoint()
        if point is not None:
            _record(runtime, row, *point)
            writer.settled()


def _save(runtime: Runtime, row: TusUpload, writer: ResumableWriter, hashes: Hashes) -> None:
    """Keep what a request sent before it broke off (not with a checksum: unverifiable)."""
    if hashes.check is not None:
        return
    offset, state = writer.finish(last=False)
    _record(runtime, row, offset, state)
    writer.settled()
    hashes.keep(row.id, offset)


def _space_left(runtime: Runtime, row: TusUpload) -> None:
    """Refuse a request the data folder has no room for (507; a bucket has room)."""
    check_free_space(
        runtime.store, runtime.settings.min_free_bytes, incoming_bytes=row.length - row.offset
    )


async def receive(
    runtime: Runtime,
    project_id: str,
    upload_id: str,
    body: AsyncIterator[bytes],
    *,
    offset: str | None,
    content_type: str | None,
    content_length: str | None,
    checksum: str | None,
) -> Received:
    """Write a request's body at the upload's offset; make the dataset once it is complete.

    Args:
        runtime: the process's runtime.
        project_id: the caller's project.
        upload_id: the upload.
        body: the request's bytes as they arrive (an error from it, a client that went
            away, keeps what arrived before: the client asks the offset and continues).
        offset: ``Upload-Offset``.
        content_type: ``Content-Type`` (``application/offset+octet-stream``).
        content_length: ``Content-Length``, if sent.
        checksum: ``Upload-Checksum``, if sent (``sha1 BASE64``).

    Raises:
        UploadMediaTypeError: another content type (415).
        UploadError: a malformed offset or checksum header (400).
        NotFoundError: no such upload in the project (404).
        UploadOffsetError: the offset is not where the upload stands (409).
        UploadLockedError: another request writes to it (423).
        UploadTooLargeError: more bytes than the upload's length (413).
        UploadChecksumError: the body does not match its checksum (460; nothing is kept).
        LocevalError: the complete file cannot become a dataset (as ``POST /datasets``).
    """
    if (content_type or "").split(";")[0].strip().lower() != OFFSET_MEDIA_TYPE:
        msg = f"Send the upload's bytes with 'Content-Type: {OFFSET_MEDIA_TYPE}'."
        raise UploadMediaTypeError(msg)
    start = parse_int(offset, "Upload-Offset")
    expected = parse_checksum(checksum)
    declared = None if content_length is None else parse_int(content_length, "Content-Length")
    await anyio.to_thread.run_sync(find_upload, runtime, project_id, upload_id)
    lock = UploadLock(runtime, upload_id)
    if not await anyio.to_thread.run_sync(lock.acquire):
        await anyio.to_thread.run_sync(lock.release)
        msg = (
            "Another request is writing to this upload at the moment; ask its offset again "
            "(HEAD) in a moment and continue from there."
        )
        raise UploadLockedError(msg)
    try:
        row = await anyio.to_thread.run_sync(find_upload, runtime, project_id, upload_id)
        _check_request(row, start, declared)
        if row.offset == row.length:  # complete: an empty request may ask for the dataset
            dataset_id = await anyio.to_thread.run_sync(_settle, runtime, row)
            return Received(row, dataset_id)
        await anyio.to_thread.run_sync(_space_left, runtime, row)
        writer = await anyio.to_thread.run_sync(
            resumable_parts(runtime.store, row.id).writer, row.offset, row.state
        )
        try:
            hashes = Hashes(row.id, start, expected, scan=runtime.store.reads_in_place)
            await _stream(runtime, row, writer, hashes, body)
            hashes.verify(expected)
            last = writer.offset == row.length

            def finish() -> None:
                new, state = writer.finish(last=last)
                _record(runtime, row, new, state)
                writer.settled()
                hashes.keep(row.id, new)

            await anyio.to_thread.run_sync(finish)
        finally:
            with anyio.CancelScope(shield=True):
                await anyio.to_thread.run_sync(writer.close)
        dataset_id = None
        if last:
            dataset_id = await anyio.to_thread.run_sync(_settle, runtime, row)
        return Received(row, dataset_id)
    finally:
        with anyio.CancelScope(shield=True):  # a cancelled request lets go of the lock too
            await anyio.to_thread.run_sync(lock.release)


def _check_request(row: TusUpload, start: int, declared: int | None) -> None:
    """Refuse a request at another offset (409) or with more bytes than are missing (413)."""
    if start != row.offset:
        msg = (
            f"The upload stands at byte {row.offset:,}, not at {start:,} (Upload-Offset); "
            "ask its offset (HEAD) and continue from there."
        )
        raise UploadOffsetError(msg)
    if declared is not None and start + declared > row.length:
        raise UploadTooLargeError(_beyond(row))


def _beyond(row: TusUpload) -> str:
    return (
        f"The request sends more bytes than the upload's length of {row.length:,} "
        f"(it stands at {row.offset:,}); send only the rest of the file."
    )


async def _stream(
    runtime: Runtime,
    row: TusUpload,
    writer: ResumableWriter,
    hashes: Hashes,
    body: AsyncIterator[bytes],
) -> None:
    """Write the body in batches of 1 MiB (in a thread: the store's writes block)."""
    batch = bytearray()
    try:
        async for chunk in body:
            if writer.offset + len(batch) + len(chunk) > row.length:
                raise UploadTooLargeError(_beyond(row))  # noqa: TRY301  (kept: what arrived)
            batch += chunk
            if len(batch) >= _BATCH_BYTES:
                data, batch = bytes(batch), bytearray()
                await anyio.to_thread.run_sync(_write, runtime, row, writer, hashes, data)
        if batch:
            data, batch = bytes(batch), bytearray()
            await anyio.to_thread.run_sync(_write, runtime, row, writer, hashes, data)
    except Exception:  # the body broke off (batch: its bytes since the last write), or a write
        with contextlib.suppress(LocevalError, OSError):  # the first error is the one to tell
            if batch:
                await anyio.to_thread.run_sync(_write, runtime, row, writer, hashes, bytes(batch))
            await anyio.to_thread.run_sync(_save, runtime, row, writer, hashes)
        raise


# -- the dataset ---------------------------------------------------------------------------


def settle(runtime: Runtime, project_id: str, upload_id: str, *, wait: bool = True) -> TusUpload:
    """Return an upload as it stands; a complete one that is no dataset yet becomes one now.

    A request cut off a moment ago may still be recording what it received: its lock is
    waited for (a few seconds), so the offset answered is the one to continue from. A
    complete upload without a dataset is one whose process died at its last byte.
    Without ``wait``, an unfinished upload is answered as recorded (a progress display).

    Raises:
        NotFoundError: no such upload in the project.
    """
    row = find_upload(runtime, project_id, upload_id)
    if row.dataset_id is not None or row.error is not None:
        return row
    if not wait and row.offset < row.length:  # progress as recorded, while it goes on
        return row
    lock = UploadLock(runtime, upload_id)
    try:
        if lock.acquire():  # a request cut off is still recording what it received
            row = find_upload(runtime, project_id, upload_id)
            if row.offset == row.length and row.dataset_id is None and row.error is None:
                with contextlib.suppress(LocevalError):  # recorded in the row's error
                    _settle(runtime, row)
    finally:
        lock.release()
    return row


def _settle(runtime: Runtime, row: TusUpload) -> str | None:
    """Make a complete upload a dataset (the lock is held); return its id.

    Raises:
        LocevalError: the file cannot become a dataset (recorded in the row's ``error``;
            a store or database outage is not recorded: the next request tries again).
    """
    if row.dataset_id is not None:
        return row.dataset_id
    if row.error is not None:
        raise UploadError(str(row.error.get("detail", "The upload could not become a dataset.")))
    adopted = _published(runtime, row)
    if adopted is not None:
        _record(runtime, row, row.offset, row.state, dataset_id=adopted.id, report=None)
        return adopted.id
    parts = resumable_parts(runtime.store, row.id)
    try:
        incoming, state = parts.assemble(row.state, row.length)
    except FileNotFoundError:
        msg = "The upload's bytes are gone from the server; send the file again."
        error = UploadError(msg)
        _record(runtime, row, row.offset, row.state, error=problem_for(error))
        raise error from None
    known, scanned = tus_hashes.settled(row.id)
    if scanned is not None and scanned[0] == row.length:  # every byte seen: its tf and poses
        incoming.held = scanned[1].finish()
    if known is not None and known[0] == row.length:
        sha256 = known[1].hexdigest()
    else:  # another process received some of it: read it back once
        digest = hashlib.sha256()
        for chunk in parts.read(state):
            digest.update(chunk)
        sha256 = digest.hexdigest()
    _record(runtime, row, row.offset, {**state, "sha256": sha256})
    received = ReceivedFile("file", row.filename, incoming, row.length, sha256, incoming.held)
    try:
        dataset, report = datasets.store_upload(
            runtime, row.project_id, received, name=row.name, tags=list(row.tags)
        )
    except ServiceUnavailableError:
        raise
    except LocevalError as err:
        incoming.abort()
        problem = problem_for(err, private=runtime.private_roots)
        _record(runtime, row, row.offset, row.state, error=problem)
        raise
    _record(
        runtime,
        row,
        row.offset,
        row.state,
        dataset_id=dataset.id,
        report=report.model_dump(mode="json"),
    )
    logger.info("Upload %s became dataset %s", row.id, dataset.id)
    return dataset.id


# -- expiry --------------------------------------------------------------------------------


def sweep_expired(runtime: Runtime, *, now: dt.datetime | None = None) -> int:
    """Remove the uploads past their expiry; return how many.

    An unfinished one's parts go (its file, or its multipart upload and tail in the
    bucket); a finished one's row goes (its dataset stays). An upload a request is writing
    to is left for the next sweep.
    """
    cutoff = now or utcnow()
    removed = 0
    with runtime.sessions() as session:
        ids = session.scalars(
            select(TusUpload.id).where(TusUpload.expires_at < cutoff).limit(_SWEEP_BATCH)
        ).all()
    for upload_id in ids:
        lock = UploadLock(runtime, upload_id)
        if not lock.acquire(0.0):
            lock.release()
            continue
        try:
            with runtime.sessions() as session:
                row = session.get(TusUpload, upload_id)
            if row is None or row.expires_at >= cutoff:
                continue
            _forget(runtime, row)
            lock.release(remove=True)
            removed += 1
        finally:
            lock.release()
    if removed:
        logger.info(
            "Removed %d expired uploads",
            removed,
            extra={"event": "uploads_expired", "uploads": removed},
        )
    return removed
