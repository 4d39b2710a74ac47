"""An upload streamed into a multipart upload of the bucket (:class:`S3Incoming`).

Part of the object-storage backend (:mod:`service.blobs.s3`): the upload's key is final from
the start; nothing is visible until it is published, and an aborted one never becomes an
object.
"""

from __future__ import annotations

import contextlib
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from typing import TYPE_CHECKING, Final, Protocol

from botocore.exceptions import BotoCoreError, ClientError

from service.blobs.base import Incoming
from service.blobs.s3client import store_errors

if TYPE_CHECKING:
    from mypy_boto3_s3 import S3Client

__all__ = [
    "PART_BYTES",
    "UPLOAD_PREFIXES",
    "Bucket",
    "S3Incoming",
    "held_key",
    "pending_key",
]

PART_BYTES: Final = 8 << 20
"""The size of an upload's parts (S3 wants at least 5 MiB but for the last)."""
_IN_FLIGHT: Final = 4  # parts sent at once: the upload holds at most this many in memory


class Bucket(Protocol):
    """What an upload needs of its store (:class:`service.blobs.s3.S3Blobs`)."""

    client: S3Client
    bucket: str
    prefix: str

    def remove_upload(self, dataset_id: str, storage_path: str) -> None:
        """Delete a published upload's object and its marker."""


class S3Incoming(Incoming):
    """An upload streamed into a multipart upload, at most a few parts in memory.

    Its key is final (``uploads/<instance>/<uuid>``): :meth:`commit` sends the last part but
    does not complete the upload, so nothing is visible yet; :meth:`publish` writes the
    pending marker and completes it, making the whole object appear at once. An upload of
    bytes that are stored already is aborted without ever becoming an object.
    """

    def __init__(self, store: Bucket, key: str) -> None:
        """Receive into ``key`` (relative to the prefix); nothing is sent before a part is full."""
        super().__init__()
        self.store = store
        self.key = key  # relative to the prefix
        self._buffer = bytearray()
        self._upload_id: str | None = None
        self._parts: list[tuple[int, Future[str]]] = []
        self._pool: ThreadPoolExecutor | None = None
        self.committed = False
        self.published = False
        self.done = False

    @property
    def _full_key(self) -> str:
        return self.store.prefix + self.key

    def _write(self, chunk: bytes) -> None:
        self._buffer += chunk
        while len(self._buffer) >= PART_BYTES:
            with memoryview(self._buffer) as view:  # one copy into the part, not two
                part = bytes(view[:PART_BYTES])
            del self._buffer[:PART_BYTES]
            self._send(part)

    def _send(self, data: bytes) -> None:
        client = self.store.client
        if self._upload_id is None:
            with store_errors():
                created = client.create_multipart_upload(
                    Bucket=self.store.bucket, Key=self._full_key
                )
            self._upload_id = created["UploadId"]
            self._pool = ThreadPoolExecutor(_IN_FLIGHT, thread_name_prefix="loceval-upload")
        pending = [f for _, f in self._parts if not f.done()]
        if len(pending) >= _IN_FLIGHT:
            wait(pending, return_when=FIRST_COMPLETED)
        for _, future in self._parts:
            if future.done():
                future.result()  # a failed part fails the upload now
        number = len(self._parts) + 1
        assert self._pool is not None  # noqa: S101  (created with the upload id)
        self._parts.append((number, self._pool.submit(self._upload_part, number, data)))

    def _upload_part(self, number: int, data: bytes) -> str:
        assert self._upload_id is not None  # noqa: S101
        with store_errors():
            answer = self.store.client.upload_part(
                Bucket=self.store.bucket,
                Key=self._full_key,
                UploadId=self._upload_id,
                PartNumber=number,
                Body=data,
            )
        return answer["ETag"]

    def commit(self) -> None:
        """See :meth:`Incoming.commit`: every part is in the store (the object is not, yet).

        An upload smaller than a part stays in memory (under 8 MiB) until :meth:`publish`.
        """
        if self.committed:
            return
        if self._upload_id is not None:
            if self._buffer:
                self._send(bytes(self._buffer))
                self._buffer = bytearray()
            for _, future in self._parts:
                future.result()
            self._close_pool()
        self.committed = True

    def publish(self, dataset_id: str) -> None:
        """Mark the upload pending for ``dataset_id``, then make it an object, whole."""
        if not self.committed or self.done:
            msg = "only a committed, not aborted upload to the bucket can be published"
            raise TypeError(msg)
        client = self.store.client
        with store_errors():
            client.put_object(
                Bucket=self.store.bucket,
                Key=self.store.prefix + pending_key(self.key),
                Body=dataset_id.encode(),
            )
            if self.held is not None:  # after the marker: a sweep deletes both with the upload
                client.put_object(
                    Bucket=self.store.bucket,
                    Key=self.store.prefix + held_key(self.key),
                    Body=self.held.to_bytes(),
                )
            if self._upload_id is None:  # smaller than one part: one request
                client.put_object(
                    Bucket=self.store.bucket, Key=self._full_key, Body=bytes(self._buffer)
                )
            else:
                parts = [{"PartNumber": n, "ETag": f.result()} for n, f in self._parts]
                client.complete_multipart_upload(
                    Bucket=self.store.bucket,
                    Key=self._full_key,
                    UploadId=self._upload_id,
                    MultipartUpload={"Parts": parts},  # type: ignore[typeddict-item]
                )
        self._buffer = bytearray()
        self.published = True

    def _close_pool(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def abort(self) -> None:
        """See :meth:`Incoming.abort` (after publishing: deletes the object and its marker)."""
        if self.done:
            return
        self.done = True
        self._buffer = bytearray()
        self._close_pool()
        with contextlib.suppress(BotoCoreError, ClientError):  # the sweep takes what stays
            if self.published:
                self.store.remove_upload("", self.key)
            elif self._upload_id is not None:
                self.store.client.abort_multipart_upload(
                    Bucket=self.store.bucket, Key=self._full_key, UploadId=self._upload_id
                )


UPLOAD_PREFIXES: Final = ("uploads/", "tus/")
"""Where uploads lie in the bucket: ``POST /datasets``'s and the resumable uploads'."""


def held_key(upload_key: str) -> str:
    """Return the key of an upload's held messages (``uploads/I/U`` -> ``held/I/U``).

    A resumable upload's: ``tus/U`` -> ``held/tus/U``.

    An MCAP upload's tf and pose messages, kept as it streamed through the API
    (:meth:`loceval.readers.rosbag.HeldMessages.to_bytes`): an evaluation reads them in one
    request instead of a ranged read per run of them between the images.
    """
    return "held/" + upload_key.removeprefix("uploads/")


def pending_key(upload_key: str) -> str:
    """Return the marker key of an upload's key (``uploads/I/U`` -> ``pending/I/U``)."""
    return "pending/" + upload_key.removeprefix("uploads/")
