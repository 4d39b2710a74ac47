"""Receive a multipart upload straight to disk, with its SHA-256 and a size limit.

Starlette's form parser spools every file to a temporary file first and checks no size, so
this module parses the request stream itself (``python-multipart``'s push parser): each
file part is written to ``incoming/<uuid>.part`` in the data directory as it arrives, hashed
on the way, and the request is refused with 413 the moment it passes the limit. Memory use
is a few chunks whatever the file size. A file is fsynced before it is handed on; on any
failure the partial files are deleted, so nothing half-received is ever visible.

The data directory keeps a reserve of free space (``min_free_bytes``): an upload whose
announced size would eat into it is refused with 507 before a byte is read, and one without
a size (or a disk filling from elsewhere) is stopped as soon as the free space drops below it.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Final

import anyio.to_thread
from python_multipart.exceptions import MultipartParseError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.requests import ClientDisconnect, Request

from service.errors import InsufficientStorageError, UploadError, UploadTooLargeError
from service.storage import BlobStore

__all__ = ["ReceivedFile", "ReceivedForm", "check_free_space", "receive_multipart"]

_MAX_FIELD_BYTES: Final = 64 * 1024
_MAX_FIELDS: Final = 200
_BATCH_BYTES: Final = 1 << 20
_FORM_OVERHEAD: Final = 1 << 20  # headers and text fields allowed beyond the file limit
_SPACE_CHECK_BYTES: Final = 16 << 20  # the free space is checked again after this many bytes


@dataclass(slots=True)
class ReceivedFile:
    """A file part, complete on disk.

    Attributes:
        field: the form field (``file``, ``reference``, ...).
        filename: the name the client gave.
        path: where it lies (under ``incoming/``; publish or delete it).
        size: bytes.
        sha256: hex digest.
    """

    field: str
    filename: str
    path: Path
    size: int
    sha256: str


@dataclass(slots=True)
class ReceivedForm:
    """What a multipart request held."""

    files: list[ReceivedFile] = field(default_factory=list)
    fields: dict[str, list[str]] = field(default_factory=dict)

    def value(self, name: str) -> str | None:
        """Return the last non-empty value of a text field, or None."""
        values = [v for v in self.fields.get(name, []) if v.strip()]
        return values[-1].strip() if values else None

    def values(self, name: str) -> list[str]:
        """Return every value of a repeated text field, in order."""
        return [v.strip() for v in self.fields.get(name, [])]

    def discard(self) -> None:
        """Delete the received files that were not published."""
        for received in self.files:
            received.path.unlink(missing_ok=True)


class _Receiver:
    """The push parser's callbacks: route part data to files or text fields."""

    def __init__(
        self,
        store: BlobStore,
        *,
        file_fields: frozenset[str],
        max_bytes: int,
        max_files: int,
        min_free_bytes: int = 0,
    ) -> None:
        self.store = store
        self.file_fields = file_fields
        self.max_bytes = max_bytes
        self.max_files = max_files
        self.min_free_bytes = min_free_bytes
        self._next_space_check = 0
        self.form = ReceivedForm()
        self.ended = False
        self._header_field = b""
        self._header_value = b""
        self._headers: dict[bytes, bytes] = {}
        self._name = ""
        self._filename: str | None = None
        self._text: bytearray | None = None
        self._fh: IO[bytes] | None = None
        self._path: Path | None = None
        self._digest = hashlib.sha256()
        self._size = 0
        self._total = 0

    def callbacks(self) -> dict[str, Callable[..., None]]:
        return {
            "on_part_begin": self._part_begin,
            "on_header_field": self._header_field_data,
            "on_header_value": self._header_value_data,
            "on_header_end": self._header_end,
            "on_headers_finished": self._headers_finished,
            "on_part_data": self._part_data,
            "on_part_end": self._part_end,
            "on_end": self._end,
        }

    def _part_begin(self) -> None:
        self._headers = {}
        self._header_field = b""
        self._header_value = b""

    def _header_field_data(self, data: bytes, start: int, end: int) -> None:
        self._header_field += data[start:end]

    def _header_value_data(self, data: bytes, start: int, end: int) -> None:
        self._header_value += data[start:end]

    def _header_end(self) -> None:
        self._headers[self._header_field.lower()] = self._header_value
        self._header_field = b""
        self._header_value = b""

    def _headers_finished(self) -> None:
        disposition, params = parse_options_header(self._headers.get(b"content-disposition"))
        if disposition != b"form-data" or b"name" not in params:
            msg = "A multipart part has no Content-Disposition form-data name; send a normal form."
            raise UploadError(msg)
        self._name = params[b"name"].decode("utf-8", "replace")
        filename = params.get(b"filename")
        self._filename = None if filename is None else filename.decode("utf-8", "replace")
        if self._filename and self._name not in self.file_fields:
            fields = " or ".join(repr(f) for f in sorted(self.file_fields))
            msg = f"The form field {self._name!r} holds a file; send files only in {fields}."
            raise UploadError(msg)
        if self._filename is not None and self._name in self.file_fields:
            if len(self.form.files) >= self.max_files:
                msg = f"Too many files in one request (at most {self.max_files}); send fewer."
                raise UploadError(msg)
            self._path = self.store.new_incoming()
            self._fh = self._path.open("xb")
            self._digest = hashlib.sha256()
            self._size = 0
        else:
            if sum(len(v) for v in self.form.fields.values()) >= _MAX_FIELDS:
                msg = f"Too many form fields (at most {_MAX_FIELDS}); send fewer."
                raise UploadError(msg)
            self._text = bytearray()

    def _part_data(self, data: bytes, start: int, end: int) -> None:
        chunk = data[start:end]
        if self._fh is not None:
            self._size += len(chunk)
            self._total += len(chunk)
            if self._total > self.max_bytes:
                raise UploadTooLargeError(_too_large(self.max_bytes))
            if self.min_free_bytes and self._total >= self._next_space_check:
                self._next_space_check = self._total + _SPACE_CHECK_BYTES
                check_free_space(self.store, self.min_free_bytes)
            with _disk_full_refused():
                self._fh.write(chunk)
            self._digest.update(chunk)
        elif self._text is not None:
            self._text += chunk
            if len(self._text) > _MAX_FIELD_BYTES:
                msg = (
                    f"The form field {self._name!r} is longer than {_MAX_FIELD_BYTES} bytes; "
                    "send files in file fields."
                )
                raise UploadError(msg)

    def _part_end(self) -> None:
        if self._fh is not None and self._path is not None:
            with _disk_full_refused():
                self._fh.flush()
                os.fsync(self._fh.fileno())
            self._fh.close()
            self._fh = None
            received = ReceivedFile(
                self._name, self._filename or "", self._path, self._size, self._digest.hexdigest()
            )
            self._path = None
            if received.size == 0 and not received.filename:
                received.path.unlink(missing_ok=True)  # a browser's empty file input
            else:
                self.form.files.append(received)
        elif self._text is not None:
            text = self._text.decode("utf-8", "replace")
            self.form.fields.setdefault(self._name, []).append(text)
            self._text = None

    def _end(self) -> None:
        self.ended = True

    def abort(self) -> None:
        """Close and delete everything received so far."""
        if self._fh is not None:
            with contextlib.suppress(OSError):  # an unflushable buffer (a full disk): it goes
                self._fh.close()
            self._fh = None
        if self._path is not None:
            self._path.unlink(missing_ok=True)
            self._path = None
        self.form.discard()


def _too_large(max_bytes: int) -> str:
    limit = f"{max_bytes / 1e6:,.0f} MB" if max_bytes >= 10**6 else f"{max_bytes:,} bytes"
    return (
        f"The upload is larger than the limit of {limit}; split the "
        "recording, or raise LOCEVAL_MAX_UPLOAD_BYTES on the server."
    )


_STORAGE_FULL: Final = (
    "The server's storage is nearly full, so the upload was not accepted (nothing of it was "
    "kept); try again later, or ask the server's administrator to free space."
)


def check_free_space(store: BlobStore, min_free_bytes: int, *, incoming_bytes: int = 0) -> None:
    """Refuse an upload that would leave less than ``min_free_bytes`` free in the data dir.

    Args:
        store: the data directory's blobs (uploads land in its ``incoming/`` folder).
        min_free_bytes: the reserve to keep; 0 checks nothing.
        incoming_bytes: bytes still to arrive (the announced size; 0 while receiving).

    Raises:
        InsufficientStorageError: the free space minus ``incoming_bytes`` is below the reserve.
    """
    if min_free_bytes <= 0:
        return
    if shutil.disk_usage(store.incoming).free - incoming_bytes < min_free_bytes:
        raise InsufficientStorageError(_STORAGE_FULL)


@contextlib.contextmanager
def _disk_full_refused() -> Iterator[None]:
    """Turn a write that failed for a full disk (ENOSPC, EDQUOT) into the 507 refusal."""
    try:
        yield
    except OSError as err:
        if err.errno in {errno.ENOSPC, errno.EDQUOT}:
            raise InsufficientStorageError(_STORAGE_FULL) from None
        raise


async def _feed(request: Request, parser: MultipartParser) -> None:
    """Push the body through the parser in 1 MB batches, in a thread (file writes block)."""
    batch = bytearray()
    async for chunk in request.stream():
        batch += chunk
        if len(batch) >= _BATCH_BYTES:
            await anyio.to_thread.run_sync(parser.write, bytes(batch))
            batch.clear()
    if batch:
        await anyio.to_thread.run_sync(parser.write, bytes(batch))
    parser.finalize()


async def receive_multipart(
    request: Request,
    store: BlobStore,
    *,
    max_bytes: int,
    file_fields: frozenset[str],
    max_files: int = 1,
    min_free_bytes: int = 0,
) -> ReceivedForm:
    """Stream a ``multipart/form-data`` request to disk.

    Args:
        request: the request, body not yet read.
        store: where the files go (``incoming/``).
        max_bytes: the limit on the sum of the file sizes.
        file_fields: the field names that take files; files in other fields are refused.
        max_files: how many files the request may hold.
        min_free_bytes: the free space the data directory keeps (0: not checked).

    Returns:
        The files (on disk, to be published or discarded by the caller) and text fields.

    Raises:
        UploadError: not multipart, malformed or truncated body, or a stray file field.
        UploadTooLargeError: more than ``max_bytes`` of files (checked on Content-Length
            first, then while receiving).
        InsufficientStorageError: the upload would leave less than ``min_free_bytes`` free
            (checked on Content-Length first, then while receiving); nothing is kept.
    """
    content_type, params = parse_options_header(request.headers.get("content-type"))
    if content_type != b"multipart/form-data" or not params.get(b"boundary"):
        fields = " or ".join(repr(f) for f in sorted(file_fields))
        msg = (
            f"Send the upload as multipart/form-data with the file in the field {fields} "
            "(curl -F FIELD=@FILE)."
        )
        raise UploadError(msg)
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > max_bytes + _FORM_OVERHEAD:
        raise UploadTooLargeError(_too_large(max_bytes))
    announced = int(declared) if declared is not None and declared.isdigit() else 0
    check_free_space(store, min_free_bytes, incoming_bytes=announced)
    receiver = _Receiver(
        store,
        file_fields=file_fields,
        max_bytes=max_bytes,
        max_files=max_files,
        min_free_bytes=min_free_bytes,
    )
    parser = MultipartParser(params[b"boundary"], receiver.callbacks())  # type: ignore[arg-type]
    try:
        await _feed(request, parser)
    except ClientDisconnect:
        receiver.abort()
        msg = "The upload was interrupted before it was complete; send it again."
        raise UploadError(msg) from None
    except MultipartParseError as err:
        receiver.abort()
        msg = f"The multipart body is malformed ({err}); send a normal multipart/form-data form."
        raise UploadError(msg) from None
    except BaseException:
        receiver.abort()
        raise
    if not receiver.ended:
        receiver.abort()
        msg = "The multipart body ended before its closing boundary (truncated); send it again."
        raise UploadError(msg)
    return receiver.form
