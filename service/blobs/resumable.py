"""The bytes of a resumable upload while it is received, in the folder or in the bucket.

A resumable upload (:mod:`service.uploads.tus`) arrives in pieces, over many requests, maybe
on several API replicas, with restarts between them. Its progress (the offset and what the
backend needs to continue, its *state*) lives in the database; its bytes live here, where
every replica reaches them:

- the folder: one file, ``tus/<id>.bin`` in the data directory, written at the offset the
  database holds (what a killed process wrote beyond it is cut off before the next write);
  on completion it is renamed into the dataset's folder, never copied.
- the bucket: an S3 multipart upload of ``tus/<id>``, in parts of
  :data:`~service.blobs.s3upload.PART_BYTES` (8 MiB; S3 wants 5 MiB but for the last). The
  bytes of a request that end between two part boundaries are kept in the bucket as one
  *tail segment* of their own (``tus/<id>.tail/<offset>``); the segments are read back once,
  when the next requests' bytes fill the part. A 2 GB file sent in 1 MB requests holds at
  most one part in memory, writes and reads each byte of it at most once more, and the
  object is put together by the store (``CompleteMultipartUpload``), never copied through
  this process. The state is ``{"upload_id", "parts": [[number, etag], ...], "segments":
  [[offset, size], ...], "tail": bytes, "assembled": bool}``.

The database is the truth: a piece of the store is only ever referred to once it was
written whole, and deleted only once the recorded state no longer refers to it, so a process
killed anywhere leaves a state the next request continues from.
"""

from __future__ import annotations

import abc
import contextlib
import os
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Final

from service.blobs.base import HEAD_BYTES, Blobs, Incoming
from service.blobs.local import LocalBlobs, LocalIncoming, disk_full_refused

if TYPE_CHECKING:
    from service.blobs.s3 import S3Blobs

__all__ = ["ResumableParts", "ResumableWriter", "resumable_parts"]

_READ_CHUNK: Final = 1 << 20
_CHECKPOINT_BYTES: Final = 8 << 20  # a folder's upload records its offset this often
_IN_FLIGHT: Final = 3  # parts sent to the bucket at once by one request


class ResumableWriter(abc.ABC):
    """The bytes of one request, appended at the upload's offset.

    :meth:`checkpoint` and :meth:`finish` return the new offset and state to record; a
    writer that is dropped without either leaves the recorded state valid.
    """

    def __init__(self, offset: int) -> None:
        """Start writing at ``offset`` (the offset the database holds)."""
        self.start = offset
        self.offset = offset

    def write(self, chunk: bytes) -> None:
        """Append ``chunk``."""
        self._write(chunk)
        self.offset += len(chunk)

    @abc.abstractmethod
    def _write(self, chunk: bytes) -> None:
        """Append ``chunk`` to the backend's copy."""

    @abc.abstractmethod
    def checkpoint(self) -> tuple[int, dict[str, Any]] | None:
        """Return the offset and state that are durable now, or None when nothing new is."""

    @abc.abstractmethod
    def finish(self, *, last: bool) -> tuple[int, dict[str, Any]]:
        """Make everything written durable; return the offset and the state to record.

        Args:
            last: the upload is complete with these bytes (the bucket sends its last part).
        """

    def settled(self) -> None:  # noqa: B027  (a folder's writer leaves nothing behind)
        """The state returned last is recorded: let go of what it no longer refers to."""

    def close(self) -> None:  # noqa: B027  (a folder's writer holds only its file)
        """Let go of what the writer holds (after :meth:`finish`, or instead of it)."""


class ResumableParts(abc.ABC):
    """Where one resumable upload's bytes lie: open, assemble, read back, remove."""

    def __init__(self, upload_id: str) -> None:
        """Name the upload (a UUID: its files and keys are named by it)."""
        self.upload_id = upload_id

    @abc.abstractmethod
    def begin(self) -> dict[str, Any]:
        """Make room for a new upload; return its first state."""

    @abc.abstractmethod
    def writer(self, offset: int, state: dict[str, Any]) -> ResumableWriter:
        """Return a writer that continues the upload at ``offset`` (its recorded state)."""

    @abc.abstractmethod
    def became(self, state: dict[str, Any], storage_path: str) -> bool:
        """Whether an assembled upload was handed on: published as ``storage_path``, or gone.

        (A process that died between publishing and recording it left the row unfinished.)
        """

    @abc.abstractmethod
    def assemble(self, state: dict[str, Any], size: int) -> tuple[Incoming, dict[str, Any]]:
        """Make the complete upload one file or object; return it and the state to record.

        The returned :class:`~service.blobs.base.Incoming` is committed and its ``head`` is
        read: :func:`service.uploads.datasets.store_upload` publishes or aborts it like any
        upload. Calling it again on the recorded state returns the same file.
        """

    @abc.abstractmethod
    def read(self, state: dict[str, Any]) -> Iterator[bytes]:
        """Yield the assembled upload's bytes (to hash it when no process saw them all)."""

    @abc.abstractmethod
    def remove(self, state: dict[str, Any]) -> None:
        """Delete whatever of the upload is stored (parts, tail, an unpublished object)."""


def resumable_parts(store: Blobs, upload_id: str) -> ResumableParts:
    """Return the parts of an upload in the store's backend."""
    if isinstance(store, LocalBlobs):
        return FolderParts(store, upload_id)
    from service.blobs.s3 import S3Blobs  # noqa: PLC0415  (boto3: the scale extra)

    if isinstance(store, S3Blobs):
        return BucketParts(store, upload_id)
    msg = f"resumable uploads are not supported by a {type(store).__name__}"  # pragma: no cover
    raise TypeError(msg)  # pragma: no cover


# -- the folder ----------------------------------------------------------------------------


class _FileIncoming(LocalIncoming):
    """A complete resumable upload's file, handed to the dataset code like a received one."""

    def __init__(self, path: Path) -> None:  # the file exists and is complete
        Incoming.__init__(self)
        self.path = path
        self._fh = None
        with path.open("rb") as fh:
            self.head = fh.read(HEAD_BYTES)


class _FileWriter(ResumableWriter):
    def __init__(self, path: Path, offset: int) -> None:
        super().__init__(offset)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        self._fh: IO[bytes] = os.fdopen(fd, "r+b")
        self._fh.truncate(offset)  # what a killed request wrote past the recorded offset
        self._fh.seek(offset)
        self._durable = offset

    def _write(self, chunk: bytes) -> None:
        with disk_full_refused():
            self._fh.write(chunk)

    def checkpoint(self) -> tuple[int, dict[str, Any]] | None:
        if self.offset - self._durable < _CHECKPOINT_BYTES:
            return None
        with disk_full_refused():
            self._fh.flush()  # a killed process's written bytes stay (the kernel holds them)
        self._durable = self.offset
        return self.offset, {}

    def finish(self, *, last: bool) -> tuple[int, dict[str, Any]]:
        del last
        with disk_full_refused():
            self._fh.flush()
            os.fsync(self._fh.fileno())
        self._durable = self.offset
        return self.offset, {}

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._fh.close()


class FolderParts(ResumableParts):
    """An upload's bytes in ``tus/<id>.bin`` of the data directory."""

    def __init__(self, store: LocalBlobs, upload_id: str) -> None:
        """Name the file."""
        super().__init__(upload_id)
        self.path = store.root / "tus" / f"{upload_id}.bin"

    def begin(self) -> dict[str, Any]:
        """See :meth:`ResumableParts.begin`: an empty file."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.touch()
        return {}

    def writer(self, offset: int, state: dict[str, Any]) -> ResumableWriter:
        """See :meth:`ResumableParts.writer`."""
        del state
        return _FileWriter(self.path, offset)

    def became(self, state: dict[str, Any], storage_path: str) -> bool:
        """See :meth:`ResumableParts.became`: the file was renamed away."""
        del state, storage_path
        return not self.path.exists()

    def assemble(self, state: dict[str, Any], size: int) -> tuple[Incoming, dict[str, Any]]:
        """See :meth:`ResumableParts.assemble`: the file itself (renamed when published)."""
        del size
        return _FileIncoming(self.path), state

    def read(self, state: dict[str, Any]) -> Iterator[bytes]:
        """See :meth:`ResumableParts.read`."""
        del state
        with self.path.open("rb") as fh:
            while chunk := fh.read(_READ_CHUNK):
                yield chunk

    def remove(self, state: dict[str, Any]) -> None:
        """See :meth:`ResumableParts.remove`."""
        del state
        self.path.unlink(missing_ok=True)


# -- the bucket ----------------------------------------------------------------------------


def _bucket_incoming(store: S3Blobs, key: str, head: bytes) -> Incoming:
    """Return a completed object of the bucket as an upload :meth:`S3Blobs.publish_upload` takes.

    Its object exists already (the multipart upload was completed by :meth:`assemble`); the
    tus row, not a pending marker, tells that it is not yet a dataset, so publishing writes
    only the held messages beside it (an MCAP file seen whole by this process), and aborting
    it (identical bytes stored already) deletes the object.
    """
    from service.blobs.s3client import store_errors  # noqa: PLC0415
    from service.blobs.s3upload import S3Incoming, held_key  # noqa: PLC0415

    class _Assembled(S3Incoming):
        def publish(self, dataset_id: str) -> None:
            del dataset_id
            if self.held is not None:  # an MCAP file's tf and poses, kept as it streamed in
                with store_errors():
                    self.store.client.put_object(
                        Bucket=self.store.bucket,
                        Key=self.store.prefix + held_key(self.key),
                        Body=self.held.to_bytes(),
                    )
            self.published = True

        def abort(self) -> None:
            if self.done:
                return
            self.done = True
            with contextlib.suppress(Exception):  # the expiry sweep takes what stays
                self.store.client.delete_object(
                    Bucket=self.store.bucket, Key=self.store.prefix + self.key
                )

    incoming = _Assembled(store, key)
    incoming.committed = True
    incoming.head = head
    return incoming


class _BucketWriter(ResumableWriter):
    """Whole parts into the multipart upload; the bytes past the last one as tail segments.

    A request's bytes that end between two part boundaries are written as one more tail
    segment (``tus/<id>.tail/<offset>``, only its own bytes): the segments are read back once,
    when the bytes after them fill the part. Each byte is so written and read at most once
    more, however small the requests are, and at most one part is held in memory.
    """

    def __init__(self, parts: BucketParts, offset: int, state: dict[str, Any]) -> None:
        super().__init__(offset)
        from service.blobs.s3upload import PART_BYTES  # noqa: PLC0415

        self.part_bytes = PART_BYTES
        self.owner = parts
        self.upload_id: str | None = state.get("upload_id")
        self.parts: list[list[Any]] = [list(p) for p in state.get("parts", [])]
        self.segments: list[list[int]] = [list(g) for g in state.get("segments", [])]
        self.pending = sum(size for _, size in self.segments)  # the recorded tail's bytes
        base = len(self.parts) * self.part_bytes
        if base + self.pending != offset:
            msg = f"the upload's state ({base} + {self.pending}) is not at {offset}"
            raise RuntimeError(msg)
        self.buffer = bytearray()
        self.buffer_start = offset
        self._pool: ThreadPoolExecutor | None = None
        self._sent: list[tuple[int, Future[str]]] = []
        self._recorded = len(self.parts)
        self._consumed: dict[int, list[list[int]]] = {}  # part number: segments read into it

    def _write(self, chunk: bytes) -> None:
        self.buffer += chunk
        while self.pending + len(self.buffer) >= self.part_bytes:
            self._send_part(self.part_bytes - self.pending)

    def _send_part(self, take: int) -> None:
        """Send the tail segments and the first ``take`` bytes of the buffer as the next part."""
        head = self.owner.read_segments(self.segments) if self.segments else b""
        with memoryview(self.buffer) as view:
            part = head + bytes(view[:take])
        del self.buffer[:take]
        self.buffer_start += take
        number = len(self.parts) + len(self._sent) + 1
        if self.segments:
            self._consumed[number] = self.segments
        self.segments, self.pending = [], 0
        self._send(number, part)

    def _send(self, number: int, data: bytes) -> None:
        if self.upload_id is None:
            self.upload_id = self.owner.create()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(_IN_FLIGHT, thread_name_prefix="loceval-tus")
        while sum(1 for _, f in self._sent if not f.done()) >= _IN_FLIGHT:
            next(f for _, f in self._sent if not f.done()).result()
        future = self._pool.submit(self.owner.upload_part, self.upload_id, number, data)
        self._sent.append((number, future))

    def _collect(self, *, wait: bool) -> None:
        """Move the sent parts that are done, in order, into ``parts``."""
        while self._sent and (wait or self._sent[0][1].done()):
            number, future = self._sent.pop(0)
            self.parts.append([number, future.result()])

    def _state(self) -> dict[str, Any]:
        tail = sum(size for _, size in self.segments)
        return {
            "upload_id": self.upload_id,
            "parts": self.parts,
            "segments": self.segments,
            "tail": tail,
        }

    def checkpoint(self) -> tuple[int, dict[str, Any]] | None:
        self._collect(wait=False)
        if len(self.parts) == self._recorded:
            return None
        self._recorded = len(self.parts)
        state = {"upload_id": self.upload_id, "parts": self.parts, "segments": [], "tail": 0}
        return len(self.parts) * self.part_bytes, state

    def finish(self, *, last: bool) -> tuple[int, dict[str, Any]]:
        if last and (self.pending or self.buffer):
            self._send_part(len(self.buffer))  # the last part may be short
        self._collect(wait=True)
        self._recorded = len(self.parts)
        if self.buffer:  # the bytes past the last whole part: one more segment
            self.owner.write_segment(self.buffer_start, bytes(self.buffer))
            self.segments.append([self.buffer_start, len(self.buffer)])
            self.buffer_start += len(self.buffer)
            self.buffer = bytearray()
        return self.offset, self._state()

    def settled(self) -> None:
        for number in [n for n in self._consumed if n <= self._recorded]:
            self.owner.delete_segments(self._consumed.pop(number))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class BucketParts(ResumableParts):
    """An upload's bytes in a multipart upload of ``tus/<id>`` and its tail object."""

    def __init__(self, store: S3Blobs, upload_id: str) -> None:
        """Name the keys."""
        super().__init__(upload_id)
        self.store = store
        self.key = f"tus/{upload_id}"

    @property
    def _full_key(self) -> str:
        return self.store.prefix + self.key

    def create(self) -> str:
        """Start the multipart upload; return its id."""
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        with store_errors():
            created = self.store.client.create_multipart_upload(
                Bucket=self.store.bucket, Key=self._full_key
            )
        return created["UploadId"]

    def upload_part(self, upload_id: str, number: int, data: bytes) -> str:
        """Send one part; return its ETag."""
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        with store_errors():
            answer = self.store.client.upload_part(
                Bucket=self.store.bucket,
                Key=self._full_key,
                UploadId=upload_id,
                PartNumber=number,
                Body=data,
            )
        return answer["ETag"]

    def _segment_key(self, offset: int) -> str:
        return f"{self._full_key}.tail/{offset:020d}"

    def read_segments(self, segments: list[list[int]]) -> bytes:
        """Return the bytes of tail segments (``[offset, size]`` each), in order."""
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        data = bytearray()
        with store_errors():
            for offset, size in segments:
                answer = self.store.client.get_object(
                    Bucket=self.store.bucket,
                    Key=self._segment_key(offset),
                    Range=f"bytes=0-{size - 1}",
                )
                data += answer["Body"].read()
        if len(data) != sum(size for _, size in segments):
            msg = f"the tail of upload {self.upload_id} holds {len(data)} bytes, not as recorded"
            raise RuntimeError(msg)
        return bytes(data)

    def write_segment(self, offset: int, data: bytes) -> None:
        """Store the bytes of a request that start at ``offset`` past the last whole part."""
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        with store_errors():
            self.store.client.put_object(
                Bucket=self.store.bucket, Key=self._segment_key(offset), Body=data
            )

    def delete_segments(self, segments: list[list[int]]) -> None:
        """Delete tail segments that a recorded part holds now (a leftover goes at the end)."""
        from botocore.exceptions import BotoCoreError, ClientError  # noqa: PLC0415

        with contextlib.suppress(BotoCoreError, ClientError):
            for offset, _ in segments:
                self.store.client.delete_object(
                    Bucket=self.store.bucket, Key=self._segment_key(offset)
                )

    def begin(self) -> dict[str, Any]:
        """See :meth:`ResumableParts.begin`: a multipart upload of ``tus/<id>``."""
        return {"upload_id": self.create(), "parts": [], "segments": [], "tail": 0}

    def writer(self, offset: int, state: dict[str, Any]) -> ResumableWriter:
        """See :meth:`ResumableParts.writer`."""
        return _BucketWriter(self, offset, state)

    def became(self, state: dict[str, Any], storage_path: str) -> bool:
        """See :meth:`ResumableParts.became`: the dataset's key, or deleted (deduplicated)."""
        del state
        return storage_path == self.key or not self.store.exists(self.key)

    def assemble(self, state: dict[str, Any], size: int) -> tuple[Incoming, dict[str, Any]]:
        """See :meth:`ResumableParts.assemble`: the store puts the parts together."""
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        client, bucket = self.store.client, self.store.bucket
        if not state.get("assembled"):
            with store_errors():
                if state.get("parts"):
                    parts = [{"PartNumber": int(n), "ETag": str(e)} for n, e in state["parts"]]
                    client.complete_multipart_upload(
                        Bucket=bucket,
                        Key=self._full_key,
                        UploadId=str(state["upload_id"]),
                        MultipartUpload={"Parts": parts},  # type: ignore[typeddict-item]
                    )
                else:  # no part was sent: the file is empty, or its tail holds it whole
                    data = self.read_segments(state.get("segments", []))
                    client.put_object(Bucket=bucket, Key=self._full_key, Body=data)
                    if state.get("upload_id"):
                        with contextlib.suppress(Exception):
                            client.abort_multipart_upload(
                                Bucket=bucket, Key=self._full_key, UploadId=state["upload_id"]
                            )
            state = {**state, "assembled": True}
            self._delete_tails()
        head = b""
        if size:
            with store_errors():
                answer = client.get_object(
                    Bucket=bucket, Key=self._full_key, Range=f"bytes=0-{HEAD_BYTES - 1}"
                )
                head = answer["Body"].read()
        return _bucket_incoming(self.store, self.key, head), state

    def read(self, state: dict[str, Any]) -> Iterator[bytes]:
        """See :meth:`ResumableParts.read`: the assembled object, streamed."""
        del state
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        with store_errors():
            answer = self.store.client.get_object(Bucket=self.store.bucket, Key=self._full_key)
            yield from answer["Body"].iter_chunks(_READ_CHUNK)

    def remove(self, state: dict[str, Any]) -> None:
        """See :meth:`ResumableParts.remove`: abort the multipart upload, delete the rest."""
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        client, bucket = self.store.client, self.store.bucket
        with store_errors():
            if state.get("upload_id") and not state.get("assembled"):
                with contextlib.suppress(Exception):  # completed or aborted meanwhile
                    client.abort_multipart_upload(
                        Bucket=bucket, Key=self._full_key, UploadId=str(state["upload_id"])
                    )
            if state.get("assembled"):
                client.delete_object(Bucket=bucket, Key=self._full_key)
        self._delete_tails()

    def _delete_tails(self) -> None:
        from service.blobs.s3client import store_errors  # noqa: PLC0415

        client, bucket = self.store.client, self.store.bucket
        with store_errors():
            pages = client.get_paginator("list_objects_v2").paginate(
                Bucket=bucket, Prefix=f"{self._full_key}.tail/"
            )
            keys = [item["Key"] for page in pages for item in page.get("Contents", [])]
            for key in keys:
                client.delete_object(Bucket=bucket, Key=key)
