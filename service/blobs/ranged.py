"""A seekable, read-only file over an object in a bucket: each read is a ranged GetObject.

Readers that seek (an MCAP file's summary at its end, a zip's central directory, a ROS 1
bag's index) read a few small pieces of a large file. :class:`RangedFile` fetches what is
read and a little more, reading ahead like a kernel does: a read that starts where the last
fetch ended doubles the next fetch (up to ``max_ahead`` bytes), any other read fetches only
``min_ahead`` more than it asks. The fetched pieces are kept up to ``max_cached`` bytes (the
least recently used go), and a read larger than ``max_ahead`` is fetched in one request and
not kept, so the memory is bounded whatever the object's size. The API inspects uploaded
bags so, and an evaluation reads a large indexed MCAP input so in its job process
(:meth:`service.blobs.s3.S3Blobs.job_input`); readers that need a real file (SQLite bags,
zipped bag folders) and inputs read whole use the local input cache
(:class:`service.blobs.cache.InputCache`).

Readers that know their reads beforehand (the MCAP index reader:
:func:`loceval.readers._mcap.read_indexed_messages`) ask for many at once with
:meth:`RangedFile.pread_many`, which sends up to ``MANY_AT_ONCE`` requests together: a ranged
read from a store costs a round trip of a few milliseconds, mostly waiting, and a camera
bag's tf is thousands of small reads (a 2 GB bag's remote inspection took 20 s one by one).

Each ranged read is a plain GET of a presigned URL of the object (made once, renewed before
it expires) with a ``Range`` header, sent through the client's own HTTP session (its TLS
settings, proxies and connection pool): boto3's request machinery (events, signing, parsing)
cost 2.5 ms of CPU per request against 0.9 ms for the GET, and the store's answers are the
same bytes. A client without that session falls back to ``GetObject``.

``fetched_bytes`` and ``requests`` count what was asked of the store.
"""

from __future__ import annotations

import bisect
import contextlib
import functools
import io
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import PurePosixPath
from typing import TYPE_CHECKING, BinaryIO, Final

from botocore.awsrequest import AWSRequest
from botocore.exceptions import BotoCoreError

from service.blobs.s3client import make_client, store_errors, unless_missing
from service.errors import StoreUnavailableError

if TYPE_CHECKING:
    from _typeshed import WriteableBuffer
    from mypy_boto3_s3 import S3Client

    from loceval.readers.rosbag import HeldMessages

__all__ = ["MANY_AT_ONCE", "MAX_AHEAD", "MIN_AHEAD", "ObjectFile", "RangedFile"]

MIN_AHEAD: Final = 4 << 10
"""Bytes fetched beyond a read that does not continue the last one (a seek)."""
MAX_AHEAD: Final = 4 << 20
"""The most bytes one sequential read-ahead fetches."""
MEMO_BYTES: Final = 64 << 20
"""The most answers of :meth:`ObjectFile.pread_many` kept for asking again (a bag's tf)."""
MANY_AT_ONCE: Final = 16
"""Requests in flight for :meth:`RangedFile.pread_many` (below the client's pool of 32)."""
_URL_LIFE_S: Final = 3600
"""How long a presigned URL is valid; it is renewed after half of it."""
_ATTEMPTS: Final = 3
"""Tries of a ranged GET that failed on the way or with a 5xx (as the client's retries)."""


class RangedFile(io.RawIOBase):
    """Read an object of a bucket as a seekable binary file, fetching what is read.

    Args:
        client: the S3 client.
        bucket: the bucket.
        key: the object's full key.
        size: its size in bytes (None: asked with a HeadObject).
        min_ahead: bytes fetched beyond a read that follows a seek.
        max_ahead: the largest read-ahead (sequential reads double it up to this).
        max_cached: the fetched bytes kept for later reads (the memory bound).
    """

    def __init__(
        self,
        client: S3Client,
        bucket: str,
        key: str,
        *,
        size: int | None = None,
        min_ahead: int = MIN_AHEAD,
        max_ahead: int = MAX_AHEAD,
        max_cached: int = 2 * MAX_AHEAD,
    ) -> None:
        """Open the object (a HeadObject when its size is not given)."""
        super().__init__()
        self._client = client
        self._bucket = bucket
        self._key = key
        if size is None:
            with store_errors():
                size = int(client.head_object(Bucket=bucket, Key=key)["ContentLength"])
        self.size = size
        self._min_ahead = min_ahead
        self._max_ahead = max_ahead
        self._max_cached = max(max_cached, max_ahead)
        self._ahead = min_ahead
        self._last_end = -1
        self._pieces: OrderedDict[int, bytes] = OrderedDict()  # start -> bytes, LRU order
        self._starts: list[int] = []  # the pieces' starts, sorted
        self._cached = 0  # their bytes
        self._counting = threading.Lock()  # pread_many's threads count their requests
        self._http = getattr(getattr(client, "_endpoint", None), "http_session", None)
        self._url: tuple[str, float] | None = None  # a presigned GET and when it was made
        self._pool: ThreadPoolExecutor | None = None  # pread_many's requests, made on first use
        self._position = 0
        self.fetched_bytes = 0
        """Bytes received from the store so far."""
        self.requests = 0
        """Ranged GetObject requests made so far."""

    @property
    def cached_bytes(self) -> int:
        """Return the bytes kept now (at most ``max_cached``)."""
        return self._cached

    # -- io.RawIOBase ----------------------------------------------------------------------

    def readable(self) -> bool:
        """Return True: the file is read-only."""
        return True

    def seekable(self) -> bool:
        """Return True: any position can be read."""
        return True

    def tell(self) -> int:
        """Return the current position."""
        return self._position

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        """Move to ``offset`` from the start, the current position or the end."""
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._position, io.SEEK_END: self.size}.get(whence)
        if base is None:
            msg = f"invalid whence ({whence})"
            raise ValueError(msg)
        if base + offset < 0:
            msg = f"negative seek position {base + offset}"
            raise OSError(msg)
        self._position = base + offset
        return self._position

    def readinto(self, buffer: WriteableBuffer) -> int:
        """Read up to ``len(buffer)`` bytes at the position into ``buffer``."""
        view = memoryview(buffer).cast("B")
        data = self.pread(len(view), self._position)
        view[: len(data)] = data
        self._position += len(data)
        return len(data)

    # -- positional reads ------------------------------------------------------------------

    def pread(self, size: int, offset: int) -> bytes:
        """Return up to ``size`` bytes at ``offset`` (fewer at the end), not moving."""
        end = min(offset + size, self.size)
        if offset >= end:
            return b""
        held = bisect.bisect_right(self._starts, offset) - 1  # the piece starting before
        if held >= 0:
            start = self._starts[held]
            piece = self._pieces[start]
            if end <= start + len(piece):
                self._pieces.move_to_end(start)
                return piece[offset - start : end - start]
        if end - offset > self._max_ahead:  # a large read: one request, nothing kept
            self._last_end = -1
            return self._fetch(offset, end)
        sequential = offset == self._last_end
        self._ahead = min(2 * self._ahead, self._max_ahead) if sequential else self._min_ahead
        stop = min(max(end, offset + self._ahead), self.size)
        piece = self._fetch(offset, stop)
        self._last_end = stop
        self._keep(offset, piece)
        return piece[: end - offset]

    def pread_many(self, reads: Sequence[tuple[int, int]]) -> list[bytes]:
        """Return the bytes of each ``(size, offset)`` read (fewer at the end), in order.

        The reads are fetched directly, ``MANY_AT_ONCE`` requests at a time, and not kept:
        what is held is the answer. Use it for reads known beforehand; the position does
        not move.
        """
        ranges = [(offset, min(offset + size, self.size)) for size, offset in reads]
        if len(ranges) <= 1:
            return [self.pread(end - start, start) for start, end in ranges]

        def fetch(span: tuple[int, int]) -> bytes:
            return self._fetch(*span) if span[0] < span[1] else b""

        if self._pool is None:  # kept for the next batch: a reader asks for many in a row
            self._pool = ThreadPoolExecutor(MANY_AT_ONCE, thread_name_prefix="loceval-ranged")
        return list(self._pool.map(fetch, ranges))

    def close(self) -> None:
        """Close the file and let its request threads go."""
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None
        super().close()

    def _keep(self, start: int, piece: bytes) -> None:
        """Keep a fetched piece, dropping the least recently used beyond ``max_cached``."""
        old = self._pieces.pop(start, None)
        if old is None:
            bisect.insort(self._starts, start)
        else:
            self._cached -= len(old)
        self._pieces[start] = piece
        self._cached += len(piece)
        while self._cached > self._max_cached:
            dropped, gone = self._pieces.popitem(last=False)
            self._starts.remove(dropped)
            self._cached -= len(gone)

    def _fetch(self, start: int, end: int) -> bytes:
        """Return the bytes ``[start, end)`` of the object (one ranged GET)."""
        data = self._get(start, end) if self._http is not None else self._get_object(start, end)
        with self._counting:
            self.requests += 1
            self.fetched_bytes += len(data)
        if len(data) != end - start:
            msg = (
                f"the store answered {len(data)} bytes for a range of {end - start}; the object "
                "changed or the store does not serve ranges"
            )
            raise OSError(msg)
        return data

    def _get_object(self, start: int, end: int) -> bytes:
        with store_errors():
            answer = self._client.get_object(
                Bucket=self._bucket, Key=self._key, Range=f"bytes={start}-{end - 1}"
            )
            data: bytes = answer["Body"].read()
        return data

    def _presigned(self, *, renew: bool = False) -> str:
        made = self._url
        if made is None or renew or time.monotonic() - made[1] > _URL_LIFE_S / 2:
            with store_errors():
                url = self._client.generate_presigned_url(
                    "get_object",
                    Params={"Bucket": self._bucket, "Key": self._key},
                    ExpiresIn=_URL_LIFE_S,
                )
            made = self._url = (url, time.monotonic())
        return made[0]

    def _get(self, start: int, end: int) -> bytes:
        """A GET of the presigned URL with a Range; retried like the client's own calls."""
        assert self._http is not None  # noqa: S101  (the caller checked)
        failure = ""
        for attempt in range(_ATTEMPTS):
            if attempt:
                time.sleep(0.1 * 2**attempt)
            request = AWSRequest(
                method="GET",
                url=self._presigned(renew=failure == "403"),
                headers={"Range": f"bytes={start}-{end - 1}"},
            ).prepare()
            try:
                answer = self._http.send(request)
                status, data = int(answer.status_code), bytes(answer.content)
            except BotoCoreError as err:  # refused, reset, timed out
                failure = type(err).__name__
                continue
            if status in {200, 206}:
                return data
            failure = str(status)
            if status < 500 and status not in {403, 408, 429}:
                break  # 404 and the like: no retry helps
        msg = (
            f"The object store cannot be used (ranged GET: {failure}); "
            "try again in a minute (GET /readyz shows when it is back)."
        )
        raise StoreUnavailableError(msg)


class ObjectFile:
    """An object in a bucket as a read-only file path for the bag readers (rosbags' ``RPath``).

    ``open()`` gives a buffered :class:`RangedFile` over it, ``pread``/``size`` read it by
    position (:class:`loceval.readers.RandomAccess`: the MCAP index reader), so a bag is read
    from the store piece by piece, never copied whole. Every reader opened shares the
    counters ``fetched_bytes`` and ``requests``.

    Args:
        client: the S3 client.
        bucket: the bucket.
        key: the object's full key.
        name: the file name (its suffix tells the readers the format).
        size: its size in bytes (None: asked with a HeadObject).
        held_key: the full key of the small messages its upload held as it streamed in
            (:meth:`loceval.readers.rosbag.HeldMessages.to_bytes`; None: none kept). They
            are fetched in one request when a reader first asks for held messages
            (:meth:`held_messages`); a missing or unreadable one reads the index instead.

    It pickles as its bucket, key, name and size with this process's ``AWS_*`` variables:
    unpickled in an evaluation's job process (a child of the forkserver, which may have
    started before they were set) it reads through a client of that process made from the
    same variables (:func:`service.blobs.s3client.make_client`). The pickle goes only to
    the job processes this one starts, over a local pipe.
    """

    def __init__(
        self,
        client: S3Client,
        bucket: str,
        key: str,
        *,
        name: str,
        size: int | None = None,
        held_key: str | None = None,
    ) -> None:
        """Open the object (a HeadObject when its size is not given)."""
        self._file = RangedFile(client, bucket, key, size=size)
        self._held_key = held_key
        self._held: HeldMessages | None = None
        self._held_lock = threading.Lock()
        self.held_bytes = 0
        """Bytes of held messages fetched (counted in :attr:`fetched_bytes` too)."""
        self._opened: list[RangedFile] = [self._file]
        self._client, self._bucket, self._key = client, bucket, key
        self.name = name
        self.size = self._file.size
        self._memo: dict[tuple[int, int], bytes] = {}
        self._memo_bytes = 0

    def __reduce__(
        self,
    ) -> tuple[
        Callable[..., ObjectFile], tuple[tuple[str, str, str | None], str, int, dict[str, str]]
    ]:
        """Pickle the object's address and the client's variables (not its connections)."""
        environ = {k: v for k, v in os.environ.items() if k.startswith("AWS_")}
        address = (self._bucket, self._key, self._held_key)
        return _reopen, (address, self.name, self.size, environ)

    def __str__(self) -> str:
        """Return the file name (what messages show)."""
        return self.name

    @property
    def suffix(self) -> str:
        """Return the file name's suffix (``.mcap``)."""
        return PurePosixPath(self.name).suffix

    @property
    def stem(self) -> str:
        """Return the file name without its suffix."""
        return PurePosixPath(self.name).stem

    def exists(self) -> bool:
        """Return True: the object was found."""
        return True

    def is_file(self) -> bool:
        """Return True: an object is a file."""
        return True

    def is_dir(self) -> bool:
        """Return False: an object is no folder."""
        return False

    def open(self, mode: str = "rb", *_args: object, **_kwargs: object) -> BinaryIO:
        """Return a new buffered reader over the object (``mode`` must be ``rb``)."""
        if mode != "rb":
            msg = f"an object in the bucket is read-only; cannot open it with mode {mode!r}"
            raise OSError(msg)
        raw = RangedFile(self._client, self._bucket, self._key, size=self.size)
        self._opened.append(raw)
        return io.BufferedReader(raw, buffer_size=64 << 10)

    def pread(self, size: int, offset: int) -> bytes:
        """Return up to ``size`` bytes at ``offset``."""
        return self._file.pread(size, offset)

    def pread_many(self, reads: Sequence[tuple[int, int]]) -> list[bytes]:
        """Return the bytes of each ``(size, offset)`` read, several requests at once.

        Answers are kept up to ``MEMO_BYTES``: a job that reads several tf chains or topics
        of one bag asks for the same index records and messages once per source.
        """
        missing = [r for r in dict.fromkeys(reads) if r not in self._memo]
        fetched = dict(zip(missing, self._file.pread_many(missing), strict=True))
        for read, data in fetched.items():
            if self._memo_bytes + len(data) <= MEMO_BYTES:
                self._memo[read] = data
                self._memo_bytes += len(data)
        return [self._memo[r] if r in self._memo else fetched[r] for r in reads]

    def held_messages(
        self, wanted: Sequence[tuple[str, str]]
    ) -> list[tuple[int, int, bytes]] | None:
        """Return the wanted channels' messages from what the upload held, or None.

        See :class:`loceval.readers.HoldsMessages`: None (no held messages kept, a wanted
        channel not among them) makes the index reader read the file itself.
        """
        held = self._load_held()
        return None if held is None else held.messages(wanted)

    def _load_held(self) -> HeldMessages | None:
        """Fetch and read the held messages once (one GET); None when there are none."""
        from loceval.readers.rosbag import HeldMessages  # noqa: PLC0415  (rosbags: jobs only)

        with self._held_lock:
            if self._held is None and self._held_key is not None:
                key, self._held_key = self._held_key, None  # asked once, found or not

                def read() -> bytes:
                    answer = self._client.get_object(Bucket=self._bucket, Key=key)
                    return answer["Body"].read()

                data = unless_missing(read)
                if data is not None:
                    self.held_bytes += len(data)
                    with contextlib.suppress(ValueError):  # another version: read the index
                        self._held = HeldMessages.from_bytes(data)
            return self._held

    @property
    def fetched_bytes(self) -> int:
        """Return the bytes fetched from the store by every reader of this object."""
        return sum(f.fetched_bytes for f in self._opened) + self.held_bytes

    @property
    def requests(self) -> int:
        """Return the ranged requests made by every reader of this object."""
        return sum(f.requests for f in self._opened)


def _reopen(
    address: tuple[str, str, str | None], name: str, size: int, environ: dict[str, str]
) -> ObjectFile:
    """Open a pickled :class:`ObjectFile` again, with a client of this process.

    ``address`` is its bucket, key and held messages' key. One object is one
    :class:`ObjectFile` here: the reference and the estimates of one bag share its answers
    (``pread_many``'s memo) and its held messages.
    """
    return _opened(address, name, size, tuple(sorted(environ.items())))


@functools.cache
def _opened(
    address: tuple[str, str, str | None],
    name: str,
    size: int,
    environ: tuple[tuple[str, str], ...],
) -> ObjectFile:
    bucket, key, held_key = address
    return ObjectFile(
        _process_client(environ), bucket, key, name=name, size=size, held_key=held_key
    )


@functools.cache
def _process_client(environ: tuple[tuple[str, str], ...]) -> S3Client:
    """Return one S3 client per ``AWS_*`` variables for the objects unpickled here.

    The variables are set in this process (a job's own, which makes no other client) so
    that boto3 reads them as it reads its environment everywhere else.
    """
    os.environ.update(environ)
    return make_client()
