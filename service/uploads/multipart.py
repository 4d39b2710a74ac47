"""Receive a multipart upload straight into the blob store, with its SHA-256 and a size limit.

Starlette's form parser spools every file to a temporary file first and checks no size, so
this module parses the request stream itself (``python-multipart``'s push parser): each
file part is written to the blob store as it arrives (``incoming/<uuid>.part`` in the data
directory, or a multipart upload to the bucket: :meth:`service.blobs.Blobs.open_incoming`),
hashed on the way, and the request is refused with 413 the moment it passes the limit. Memory
use is a few chunks (with a bucket, a few parts) whatever the file size. A file is made
durable before it is handed on; on any failure the partial files (or multipart uploads) are
deleted, so nothing half-received is ever visible.

The data directory keeps a reserve of free space (``min_free_bytes``): an upload whose
announced size would eat into it is refused with 507 before a byte is read, and no write of
one without a size (or of one the disk filled under from elsewhere) passes it: the free space
is asked again whenever the bytes written since the last answer would reach the reserve.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import AsyncIterator, Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Final, Protocol
from urllib.parse import unquote_to_bytes

import anyio.to_thread
from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, parse_options_header

from service.blobs import Blobs, Incoming
from service.blobs.local import STORAGE_FULL, LocalIncoming
from service.errors import InsufficientStorageError, UploadError, UploadTooLargeError

if TYPE_CHECKING:
    from loceval.readers.rosbag import HeldMessages, McapScan

__all__ = [
    "INTERRUPTED",
    "ReceivedFile",
    "ReceivedForm",
    "UploadBody",
    "check_free_space",
    "mcap_scan",
    "receive_multipart",
]

_MAX_FIELD_BYTES: Final = 64 * 1024
_MAX_FIELDS: Final = 200
_BATCH_BYTES: Final = 1 << 20
_FORM_OVERHEAD: Final = 1 << 20  # headers and text fields allowed beyond the file limit
_SPACE_CHECK_BYTES: Final = 16 << 20  # the free space is asked again after this many bytes
_MAX_HEADER_BYTES: Final = 16 * 1024  # all header lines of one part
_MAX_HEADERS: Final = 16  # header lines in one part
_BOUNDARY: Final = re.compile(r"[0-9A-Za-z'()+_,\-./:=? ]{0,69}[0-9A-Za-z'()+_,\-./:=?]")
"""RFC 2046's boundary: 1 to 70 characters of ``bchars``, not ending in a space."""
_EXTENDED_FILENAME: Final = re.compile(rb"(?:^|;)\s*filename\*\s*=\s*([^;]*)", re.IGNORECASE)
_EXTENDED_VALUE: Final = re.compile(rb"([A-Za-z0-9!#$&+^_`{}~-]+)'[A-Za-z0-9-]*'(.*)")
INTERRUPTED: Final = "The upload was interrupted before it was complete; send it again."
"""What a client that went away mid-body is told (the routes raise it as an UploadError)."""


class UploadBody(Protocol):
    """A request's body as it arrives, with its headers (Starlette's ``Request`` is one).

    A body whose client goes away raises from :meth:`stream`; whatever was received is
    deleted before that error goes on (the HTTP side names it: :mod:`service.api.multipart`).
    """

    @property
    def headers(self) -> Mapping[str, str]:
        """The request's headers (``content-type``, ``content-length``), case-insensitive."""
        ...

    def stream(self) -> AsyncIterator[bytes]:
        """The body's bytes, in the chunks they arrive in."""
        ...


@dataclass(slots=True)
class ReceivedFile:
    """A file part, complete in the blob store.

    Attributes:
        field: the form field (``file``, ``reference``, ...).
        filename: the name the client gave.
        incoming: the received bytes (publish them with the store, or abort them).
        size: bytes.
        sha256: hex digest.
        held: an MCAP file's small messages (tf, poses), kept as they streamed past for
            the inspection of a file read where it lies (:mod:`loceval.readers.rosbag.held`);
            None for other files and stores.
    """

    field: str
    filename: str
    incoming: Incoming
    size: int
    sha256: str
    held: HeldMessages | None = None

    @property
    def path(self) -> Path:
        """Where a file received into the data folder lies (under ``incoming/``)."""
        if not isinstance(self.incoming, LocalIncoming):
            msg = "the upload went to the object store, not to a local file"
            raise TypeError(msg)
        return self.incoming.path


@dataclass(slots=True)
class ReceivedForm:
    """What a multipart request held."""

    files: list[ReceivedFile] = field(default_factory=list)
    fields: dict[str, list[str]] = field(default_factory=dict)

    def value(self, name: str) -> str | None:
        """Return the one non-empty value of a single-valued text field, or None.

        Raises:
            UploadError: the field was sent more than once with a value (one of them
                would be dropped without a word).
        """
        values = [v.strip() for v in self.fields.get(name, []) if v.strip()]
        if len(values) > 1:
            msg = f"The form field {name!r} was sent {len(values)} times; send it once."
            raise UploadError(msg)
        return values[0] if values else None

    def values(self, name: str) -> list[str]:
        """Return every value of a repeated text field, in order."""
        return [v.strip() for v in self.fields.get(name, [])]

    def discard(self) -> None:
        """Delete the received files that were not published."""
        for received in self.files:
            received.incoming.abort()


class _Receiver:
    """The push parser's callbacks: route part data to files or text fields."""

    def __init__(
        self,
        store: Blobs,
        *,
        file_fields: frozenset[str],
        text_fields: frozenset[str] | None,
        max_bytes: int,
        max_files: int,
        min_free_bytes: int = 0,
    ) -> None:
        self.store = store
        self.file_fields = file_fields
        self.text_fields = text_fields
        self.max_bytes = max_bytes
        self.max_files = max_files
        self.min_free_bytes = min_free_bytes
        self._room = 0  # bytes that may be written before the free space is asked again
        self.form = ReceivedForm()
        self.ended = False
        self._header_field = b""
        self._header_value = b""
        self._header_bytes = 0
        self._headers: dict[bytes, bytes] = {}
        self._name = ""
        self._filename: str | None = None
        self._text: bytearray | None = None
        self._fh: Incoming | None = None
        self._scan: McapScan | None = None
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
        self._header_bytes = 0

    def _count_header_bytes(self, size: int) -> None:
        self._header_bytes += size
        if self._header_bytes > _MAX_HEADER_BYTES:
            msg = (
                f"A multipart part's headers are longer than {_MAX_HEADER_BYTES // 1024} KiB; "
                "send a normal form (a file name of a few hundred characters at most)."
            )
            raise UploadError(msg)

    def _header_field_data(self, data: bytes, start: int, end: int) -> None:
        self._count_header_bytes(end - start)
        self._header_field += data[start:end]

    def _header_value_data(self, data: bytes, start: int, end: int) -> None:
        self._count_header_bytes(end - start)
        self._header_value += data[start:end]

    def _header_end(self) -> None:
        if len(self._headers) >= _MAX_HEADERS:
            msg = f"A multipart part has more than {_MAX_HEADERS} headers; send a normal form."
            raise UploadError(msg)
        self._headers[self._header_field.lower()] = self._header_value
        self._header_field = b""
        self._header_value = b""

    def _headers_finished(self) -> None:
        raw = self._headers.get(b"content-disposition", b"")
        disposition, params = parse_options_header(raw)
        if disposition.lower() != b"form-data" or not params.get(b"name"):
            msg = (
                "A multipart part has no Content-Disposition: form-data with a name; "
                "send a normal multipart/form-data form."
            )
            raise UploadError(msg)
        self._name = _utf8(params[b"name"], "A form field's name")
        self._filename = _part_filename(raw, params.get(b"filename"))
        if self._filename and self._name not in self.file_fields:
            fields = " or ".join(repr(f) for f in sorted(self.file_fields))
            msg = f"The form field {_shown(self._name)} holds a file; send files only in {fields}."
            raise UploadError(msg)
        texts = frozenset({self._name}) if self.text_fields is None else self.text_fields
        readable = self.file_fields | texts
        if self._filename is None and self._name not in readable:
            known = ", ".join(repr(f) for f in sorted(readable))
            msg = (
                f"The form field {_shown(self._name)} is not one this endpoint reads; "
                f"send only {known}."
            )
            raise UploadError(msg)
        if self._filename is not None and self._name in self.file_fields:
            if len(self.form.files) >= self.max_files:
                msg = f"Too many files in one request (at most {self.max_files}); send fewer."
                raise UploadError(msg)
            self._fh = self.store.open_incoming()
            self._scan = mcap_scan() if self.store.reads_in_place else None
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
            if self.min_free_bytes:
                self._make_room(len(chunk))
            self._fh.write(chunk)  # a local file's full disk is refused there (507)
            self._digest.update(chunk)
            if self._scan is not None:
                self._scan.feed(chunk)
        elif self._text is not None:
            self._text += chunk
            if len(self._text) > _MAX_FIELD_BYTES:
                msg = (
                    f"The form field {_shown(self._name)} is longer than {_MAX_FIELD_BYTES} bytes; "
                    "send files in file fields."
                )
                raise UploadError(msg)

    def _make_room(self, size: int) -> None:
        """Refuse a write of ``size`` bytes that would eat into the free-space reserve.

        The free space is asked (one statvfs) when the room left by the last answer is
        used up, and at least every 16 MB (other writers use the disk too), so no write
        passes the reserve by more than what others wrote meanwhile.

        Raises:
            InsufficientStorageError: less than ``size`` bytes above the reserve.
        """
        if self._room < size:
            free = self.store.free_bytes()
            if free is None:  # a bucket: the upload touches no local disk
                self._room = _SPACE_CHECK_BYTES
                return
            self._room = min(free - self.min_free_bytes, _SPACE_CHECK_BYTES)
            if self._room < size:
                raise InsufficientStorageError(STORAGE_FULL)
        self._room -= size

    def _part_end(self) -> None:
        if self._fh is not None:
            self._fh.commit()
            received = ReceivedFile(
                self._name,
                self._filename or "",
                self._fh,
                self._size,
                self._digest.hexdigest(),
                None if self._scan is None else self._scan.finish(),
            )
            self._fh.held = received.held  # a bucket stores them beside the object
            self._fh = None
            self._scan = None
            if received.size == 0 and not received.filename:
                received.incoming.abort()  # a browser's empty file input
            else:
                self.form.files.append(received)
        elif self._text is not None:
            text = _utf8(bytes(self._text), f"The form field {_shown(self._name)}")
            self.form.fields.setdefault(self._name, []).append(text)
            self._text = None

    def _end(self) -> None:
        self.ended = True

    def abort(self) -> None:
        """Close and delete everything received so far."""
        if self._fh is not None:
            self._fh.abort()
            self._fh = None
        self._scan = None
        self.form.discard()


def mcap_scan() -> McapScan:
    """Return a scan that keeps an MCAP upload's tf and pose messages as they stream past.

    Imported here: the bag readers (rosbags) load only in an API that stores into a bucket.
    """
    from loceval.readers.rosbag import McapScan  # noqa: PLC0415

    return McapScan()


def _shown(name: str) -> str:
    """Return a client's field name quoted for a message, shortened when it is long."""
    return repr(name if len(name) <= 60 else name[:57] + "...")


def _utf8(data: bytes, what: str) -> str:
    """Decode a text the client sent; refuse one that is not UTF-8 (never guess)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        msg = f"{what} is not UTF-8 text; send text fields and names in UTF-8."
        raise UploadError(msg) from None


def _part_filename(disposition: bytes, plain: bytes | None) -> str | None:
    """Return a part's file name: RFC 5987 ``filename*`` first, then ``filename``.

    Plain names that are not UTF-8 are read as Latin-1 (what old clients send); the name is
    display text only, sanitised where it is stored.

    Raises:
        UploadError: a ``filename*`` that is not ``charset'lang'percent-encoded``.
    """
    extended = _EXTENDED_FILENAME.search(disposition)
    if extended is not None:
        value = _EXTENDED_VALUE.fullmatch(extended.group(1).strip().strip(b'"'))
        charset = value.group(1).decode("ascii").lower() if value else ""
        if value is not None and charset in {"utf-8", "iso-8859-1"}:
            try:
                return unquote_to_bytes(value.group(2)).decode(charset)
            except UnicodeDecodeError:
                pass
        msg = (
            "A part's Content-Disposition has a malformed filename*; send "
            "filename*=UTF-8''NAME (percent-encoded) or a plain filename."
        )
        raise UploadError(msg)
    if plain is None:
        return None
    try:
        return plain.decode("utf-8")
    except UnicodeDecodeError:
        return plain.decode("latin-1")


def _too_large(max_bytes: int) -> str:
    limit = f"{max_bytes / 1e6:,.0f} MB" if max_bytes >= 10**6 else f"{max_bytes:,} bytes"
    return (
        f"The upload is larger than the limit of {limit}; split the "
        "recording, or raise LOCEVAL_MAX_UPLOAD_BYTES on the server."
    )


def check_free_space(store: Blobs, min_free_bytes: int, *, incoming_bytes: int = 0) -> None:
    """Refuse an upload that would leave less than ``min_free_bytes`` free in the store.

    With a bucket an upload touches no local disk and is not refused here (the workers'
    input cache keeps the reserve on their disks).

    Args:
        store: the blob store (uploads land in its ``incoming/`` folder or its bucket).
        min_free_bytes: the reserve to keep; 0 checks nothing.
        incoming_bytes: bytes still to arrive (the announced size; 0 while receiving).

    Raises:
        InsufficientStorageError: the free space minus ``incoming_bytes`` is below the reserve.
    """
    if not store.check_free_space(min_free_bytes, incoming_bytes=incoming_bytes):
        raise InsufficientStorageError(STORAGE_FULL)


async def _feed(request: UploadBody, parser: MultipartParser) -> None:
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
    request: UploadBody,
    store: Blobs,
    *,
    max_bytes: int,
    file_fields: frozenset[str],
    text_fields: frozenset[str] | None = None,
    max_files: int = 1,
    min_free_bytes: int = 0,
) -> ReceivedForm:
    """Stream a ``multipart/form-data`` request into the blob store.

    Args:
        request: the request, body not yet read (the HTTP side's own receiver,
            :func:`service.api.multipart.receive_multipart`, also names a client that went
            away).
        store: where the files go (``incoming/`` of a folder, or the bucket).
        max_bytes: the limit on the sum of the file sizes.
        file_fields: the field names that take files; files in other fields are refused.
        text_fields: the text fields the route reads; others are refused, so a misspelt
            field is not dropped without a word (None: any).
        max_files: how many files the request may hold.
        min_free_bytes: the free space the data directory keeps (0: not checked).

    Returns:
        The files (received, to be published or discarded by the caller) and text fields.

    Raises:
        UploadError: not multipart, malformed or truncated body, or a stray file field.
        UploadTooLargeError: more than ``max_bytes`` of files (checked on Content-Length
            first, then while receiving).
        InsufficientStorageError: the upload would leave less than ``min_free_bytes`` free
            (checked on Content-Length first, then while receiving); nothing is kept.
    """
    content_type, params = parse_options_header(request.headers.get("content-type"))
    if content_type.lower() != b"multipart/form-data" or not params.get(b"boundary"):
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
    boundary = params[b"boundary"]
    if not _BOUNDARY.fullmatch(boundary.decode("latin-1")):
        msg = (
            f"The multipart boundary ({len(boundary)} characters) is not valid: RFC 2046 allows "
            "1 to 70 letters, digits and '()+_,-./:=? characters; let the HTTP client choose it."
        )
        raise UploadError(msg)
    receiver = _Receiver(
        store,
        file_fields=file_fields,
        text_fields=text_fields,
        max_bytes=max_bytes,
        max_files=max_files,
        min_free_bytes=min_free_bytes,
    )
    parser = MultipartParser(boundary, receiver.callbacks())  # type: ignore[arg-type]
    try:
        await _feed(request, parser)
    except FormParserError as err:
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
