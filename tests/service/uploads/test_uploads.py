"""The streaming multipart receiver, driven directly with a synthetic ASGI request."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest
from starlette.requests import Request

from service.api.multipart import receive_multipart
from service.blobs.local import LocalBlobs
from service.errors import UploadError, UploadTooLargeError
from service.uploads.multipart import ReceivedForm

BOUNDARY = "loceval-test-boundary"
CONTENT_TYPE = f"multipart/form-data; boundary={BOUNDARY}"


class _Body:
    """The receive() side of an ASGI request: chunks, then (optionally) a disconnect."""

    def __init__(self, chunks: Iterable[bytes], *, disconnect: bool = False) -> None:
        self.messages: list[dict[str, Any]] = [
            {"type": "http.request", "body": chunk, "more_body": True} for chunk in chunks
        ]
        if disconnect:
            self.messages.append({"type": "http.disconnect"})
        else:
            self.messages.append({"type": "http.request", "body": b"", "more_body": False})
        self.received = 0

    async def __call__(self) -> dict[str, Any]:
        self.received += 1
        if not self.messages:
            return {"type": "http.disconnect"}
        return self.messages.pop(0)


def part(name: str, value: bytes, *, filename: str | None = None) -> bytes:
    """Return one form-data part (with its leading boundary line)."""
    disposition = f'form-data; name="{name}"'
    if filename is not None:
        disposition += f'; filename="{filename}"'
    head = f"--{BOUNDARY}\r\nContent-Disposition: {disposition}\r\n"
    if filename is not None:
        head += "Content-Type: application/octet-stream\r\n"
    return head.encode() + b"\r\n" + value + b"\r\n"


def form(*parts: bytes) -> bytes:
    """Return a whole multipart body with its closing boundary."""
    return b"".join(parts) + f"--{BOUNDARY}--\r\n".encode()


def chunked(data: bytes, size: int) -> list[bytes]:
    """Split bytes into chunks of ``size``."""
    return [data[i : i + size] for i in range(0, len(data), size)]


def request(
    body: _Body, *, content_type: str = CONTENT_TYPE, content_length: int | None = None
) -> Request:
    """Return a Starlette request whose body comes from ``body``."""
    headers = [(b"content-type", content_type.encode())]
    if content_length is not None:
        headers.append((b"content-length", str(content_length).encode()))
    scope = {
        "type": "http",
        "method": "POST",
        "path": "/upload",
        "headers": headers,
        "query_string": b"",
    }
    return Request(scope, body)


def receive(
    body: _Body,
    store: LocalBlobs,
    *,
    max_bytes: int = 10**9,
    file_fields: Iterable[str] = ("file",),
    max_files: int = 1,
    content_type: str = CONTENT_TYPE,
    content_length: int | None = None,
) -> ReceivedForm:
    """Run receive_multipart to completion."""

    async def run() -> ReceivedForm:
        return await receive_multipart(
            request(body, content_type=content_type, content_length=content_length),
            store,
            max_bytes=max_bytes,
            file_fields=frozenset(file_fields),
            max_files=max_files,
        )

    return anyio.run(run)


@pytest.fixture
def store(tmp_path: Path) -> LocalBlobs:
    """A blob store in an empty data folder."""
    return LocalBlobs(tmp_path / "data")


def incoming(store: LocalBlobs) -> list[Path]:
    """Return what lies in incoming/."""
    return sorted(store.incoming.iterdir())


def test_multi_chunk_file_hash_and_size(store: LocalBlobs, rng: np.random.Generator) -> None:
    """A 2.5 MB file sent in 64 KiB chunks lands whole, with the right SHA-256 and size."""
    payload = rng.bytes(2_500_000) + b"\r\n--not-the-boundary\r\n" + rng.bytes(1000)
    data = form(
        part("name", b"site A"), part("file", payload, filename="run.mcap"), part("tags", b"a,b")
    )
    body = _Body(chunked(data, 65_536))
    received = receive(body, store)
    assert len(received.files) == 1
    file = received.files[0]
    assert file.field == "file"
    assert file.filename == "run.mcap"
    assert file.size == len(payload)
    assert file.sha256 == hashlib.sha256(payload).hexdigest()
    assert file.path.read_bytes() == payload
    assert file.path.parent == store.incoming
    assert received.value("name") == "site A"
    assert received.values("tags") == ["a,b"]
    received.discard()
    assert incoming(store) == []


@pytest.mark.parametrize("size", [1, 7, 100])
def test_boundaries_split_across_chunks(store: LocalBlobs, size: int) -> None:
    """Tiny chunks split the boundary and headers anywhere; the parts come out intact."""
    payload = b"1700000000.0 0 0 0\r\n" * 20
    data = form(part("file", payload, filename="a.txt"), part("name", b"n\xc3\xa4me"))
    received = receive(_Body(chunked(data, size)), store)
    assert received.files[0].path.read_bytes() == payload
    assert received.value("name") == "näme"
    received.discard()


def test_oversize_file_removed_midstream(store: LocalBlobs, rng: np.random.Generator) -> None:
    """Passing the limit while receiving raises 413's error and leaves no partial file."""
    data = form(part("file", rng.bytes(3_000_000), filename="big.bag"))
    body = _Body(chunked(data, 65_536))
    with pytest.raises(UploadTooLargeError, match=r"larger than the limit of 100,000 bytes"):
        receive(body, store, max_bytes=100_000)
    assert incoming(store) == []
    assert body.messages  # refused at the first 1 MB batch, not after reading everything


def test_announced_oversize_refused_before_reading(store: LocalBlobs) -> None:
    """A Content-Length far over the limit is refused without reading the body."""
    body = _Body([b"x" * 10])
    with pytest.raises(UploadTooLargeError, match=r"LOCEVAL_MAX_UPLOAD_BYTES"):
        receive(body, store, max_bytes=1000, content_length=5 * 1024 * 1024)
    assert body.received == 0
    assert incoming(store) == []


def test_limit_counts_all_files(store: LocalBlobs) -> None:
    """The limit is on the sum of the files: two of 600 bytes exceed 1000."""
    data = form(
        part("reference", b"r" * 600, filename="r.txt"),
        part("estimate", b"e" * 600, filename="e.txt"),
    )
    with pytest.raises(UploadTooLargeError, match=r"1,000 bytes"):
        receive(
            _Body([data]), store, max_bytes=1000, file_fields=("reference", "estimate"), max_files=2
        )
    assert incoming(store) == []


def test_disconnect_removes_partial_file(store: LocalBlobs) -> None:
    """A client that goes away mid-file leaves nothing behind."""
    head = part("file", b"1 2 3 4\n" * 1000, filename="a.txt")[:-10]
    with pytest.raises(UploadError, match=r"interrupted before it was complete"):
        receive(_Body([head], disconnect=True), store)
    assert incoming(store) == []


def test_truncated_body_removes_files(store: LocalBlobs) -> None:
    """A body without its closing boundary is refused, and the complete parts go too."""
    data = part("file", b"complete file", filename="a.txt") + part("name", b"x")[:-5]
    with pytest.raises(UploadError, match=r"ended before its closing boundary"):
        receive(_Body([data]), store)
    assert incoming(store) == []


def test_error_in_second_file_removes_first(store: LocalBlobs) -> None:
    """A failure after one file was complete removes that file as well."""
    data = form(
        part("reference", b"first" * 100, filename="r.txt"),
        part("estimate", b"second" * 1000, filename="e.txt"),
    )
    with pytest.raises(UploadTooLargeError, match=r"larger than the limit"):
        receive(
            _Body(chunked(data, 256)),
            store,
            max_bytes=2000,
            file_fields=("reference", "estimate"),
            max_files=2,
        )
    assert incoming(store) == []


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"this is no multipart body", r"malformed"),
        (
            f"--{BOUNDARY}\r\nContent-Type: text/plain\r\n\r\nx\r\n--{BOUNDARY}--\r\n".encode(),
            r"no Content-Disposition: form-data with a name",
        ),
        (
            f'--{BOUNDARY}\r\nContent-Disposition: attachment; name="file"\r\n\r\nx\r\n'
            f"--{BOUNDARY}--\r\n".encode(),
            r"no Content-Disposition: form-data with a name",
        ),
        (b"", r"ended before its closing boundary"),
    ],
)
def test_malformed_bodies(store: LocalBlobs, data: bytes, match: str) -> None:
    """Bodies that are not a normal form are refused with what to send instead."""
    with pytest.raises(UploadError, match=match):
        receive(_Body([data]), store)
    assert incoming(store) == []


@pytest.mark.parametrize(
    "content_type",
    ["application/json", "multipart/form-data", "text/plain; boundary=x", ""],
)
def test_not_multipart(store: LocalBlobs, content_type: str) -> None:
    """A content type other than multipart/form-data with a boundary is refused unread."""
    body = _Body([form(part("file", b"x", filename="a.txt"))])
    with pytest.raises(UploadError, match=r"multipart/form-data with the file in the field 'file'"):
        receive(body, store, content_type=content_type)
    assert body.received == 0


def test_text_field_count_limit(store: LocalBlobs) -> None:
    """200 text fields are accepted; the 201st is refused."""
    fields = [part(f"f{i}", b"v") for i in range(200)]
    received = receive(_Body([form(*fields)]), store)
    assert sum(len(v) for v in received.fields.values()) == 200
    with pytest.raises(UploadError, match=r"Too many form fields \(at most 200\)"):
        receive(_Body([form(*fields, part("one_more", b"v"))]), store)


def test_text_field_length_limit(store: LocalBlobs) -> None:
    """A text field over 64 KiB is refused (files belong in file fields)."""
    with pytest.raises(UploadError, match=r"'name' is longer than 65536 bytes"):
        receive(_Body([form(part("name", b"n" * 70_000))]), store)


def test_file_in_non_file_field(store: LocalBlobs) -> None:
    """A file sent in a text field (curl -F name=@file) is refused, not read as text."""
    data = form(part("file", b"1 0 0 0\n", filename="a.txt"), part("tags", b"x", filename="t.txt"))
    with pytest.raises(UploadError, match=r"'tags' holds a file; send files only in 'file'"):
        receive(_Body([data]), store)
    assert incoming(store) == []


def test_too_many_files(store: LocalBlobs) -> None:
    """A second file where one is allowed is refused, and the first is removed."""
    data = form(part("file", b"a" * 100, filename="a.txt"), part("file", b"b", filename="b.txt"))
    with pytest.raises(UploadError, match=r"Too many files in one request \(at most 1\)"):
        receive(_Body([data]), store, max_files=1)
    assert incoming(store) == []


def test_browser_empty_file_input_is_dropped(store: LocalBlobs) -> None:
    """An empty file part without a name (a browser's unused file input) is no file."""
    received = receive(_Body([form(part("file", b"", filename=""), part("name", b"x"))]), store)
    assert received.files == []
    assert received.value("name") == "x"
    assert incoming(store) == []


def test_empty_named_file_is_kept(store: LocalBlobs) -> None:
    """An empty file with a name is a file (the dataset layer refuses it as empty)."""
    received = receive(_Body([form(part("file", b"", filename="empty.txt"))]), store)
    assert [(f.filename, f.size) for f in received.files] == [("empty.txt", 0)]
    assert received.files[0].sha256 == hashlib.sha256(b"").hexdigest()
    received.discard()
    assert incoming(store) == []


def test_repeated_fields_and_values(store: LocalBlobs) -> None:
    """Repeated fields keep their order; value() takes the last non-blank one."""
    data = form(
        part("estimate_selector", b" /a "),
        part("estimate_selector", b""),
        part("estimate_selector", b"/c"),
        part("name", b"first"),
        part("name", b"  "),
    )
    received = receive(_Body([data]), store)
    assert received.values("estimate_selector") == ["/a", "", "/c"]
    assert received.value("name") == "first"
    assert received.value("missing") is None
