"""Read a few channels of an indexed MCAP file without reading the rest.

A camera bag is mostly image payload; the tf messages are a fraction of a percent of it.
rosbags reads (and for compressed files decompresses) every chunk that holds a wanted
message, which costs more than reading the whole file. When the MCAP file is indexed and the
chunks that hold the wanted messages are stored uncompressed (rosbags' writer does so unless
asked to compress), the MCAP summary says where every message of a channel is: the chunk
indexes point to message index records, which hold each message's offset inside its chunk.
:func:`read_indexed_messages` follows them and reads only those records.

The reads are known before any is made (the summary gives each message index's place and
length), so they are asked for in batches: a source that can serve several reads at once (an
object in a bucket, :meth:`RandomAccess.pread_many`) overlaps their round trips; a local file
reads them one after another.

Anything unexpected (no summary, no chunk index, compressed chunks, a record that does not
match its index) makes it return None, and the caller reads the file through rosbags, which
then reports a damaged file properly. Record layouts follow the MCAP specification
(https://mcap.dev/spec).
"""

from __future__ import annotations

import bisect
import os
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Protocol, runtime_checkable

__all__ = [
    "MAGIC",
    "NOT_SERVABLE",
    "OP_CHANNEL",
    "OP_CHUNK",
    "OP_CHUNK_INDEX",
    "OP_FOOTER",
    "OP_MESSAGE",
    "OP_SCHEMA",
    "RECORD_HEAD",
    "HoldsMessages",
    "RandomAccess",
    "index_serves",
    "parse_channel",
    "parse_schema",
    "read_indexed_messages",
]

MAGIC = b"\x89MCAP0\r\n"
OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x02, 0x03, 0x04, 0x05, 0x06
OP_MESSAGE_INDEX, OP_CHUNK_INDEX = 0x07, 0x08
_FOOTER_SIZE = 1 + 8 + 20 + len(MAGIC)
_FIRST_READ = 512
"""Bytes read past a message's start; most tf messages fit, larger ones take a second read."""
_MAX_RUN_GAP = 64 * 1024
"""Messages closer than this are read with one call (skipping the bytes between)."""
_MAX_RUN = 1024**2
"""Longest stretch read with one call."""
_BATCH = 64
"""Reads asked for at once: the message runs of a group are held at most this many at a time
(a run is up to ``_MAX_RUN`` bytes)."""
_GROUP = 256
"""Chunks read together: their index reads are held until their messages are read."""
_SPILL = 16 * 1024
"""Bytes read past a chunk's message index records: the next chunk's first messages."""
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_CHUNK_INDEX_HEAD = struct.Struct("<QQQQ")


_ChunkIndex = tuple[int, dict[int, int], int, str]
"""A chunk index: the chunk's start, its message index offsets by channel, where its message
index records end, and its compression."""


class _NotServableError(Exception):
    """The file cannot be served from its index; read it the ordinary way."""


NOT_SERVABLE = (_NotServableError, struct.error, UnicodeDecodeError, OSError)
"""What reading the index raises when it cannot serve: unusable, cut short or garbled."""


class RandomAccess(Protocol):
    """Bytes read by position: a local file, or an object read with ranged requests."""

    @property
    def size(self) -> int:
        """The size in bytes."""
        ...

    def pread(self, size: int, offset: int) -> bytes:
        """Return up to ``size`` bytes at ``offset``."""
        ...


@runtime_checkable
class ManyAtOnce(RandomAccess, Protocol):
    """Bytes read by position, several reads at once (their waits overlap)."""

    def pread_many(self, reads: Sequence[tuple[int, int]]) -> list[bytes]:
        """Return the bytes of each ``(size, offset)`` read, in order."""
        ...


@runtime_checkable
class HoldsMessages(Protocol):
    """A file whose small messages are held in memory already (read as it was uploaded)."""

    def held_messages(
        self, wanted: Sequence[tuple[str, str]]
    ) -> list[tuple[int, int, bytes]] | None:
        """Return the wanted channels' messages as :func:`read_indexed_messages` does.

        None when they were not all held: the file is then read through its index.
        """
        ...


def _pread_many(src: RandomAccess, reads: Sequence[tuple[int, int]]) -> Iterator[bytes]:
    """Yield each ``(size, offset)`` read's bytes in order, ``_BATCH`` reads asked at once."""
    many = src.pread_many if isinstance(src, ManyAtOnce) else None
    for first in range(0, len(reads), _BATCH):
        batch = reads[first : first + _BATCH]
        yield from many(batch) if many is not None else (src.pread(n, at) for n, at in batch)


class _LocalFile:
    """A file descriptor as :class:`RandomAccess`."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.size = os.fstat(fd).st_size

    def pread(self, size: int, offset: int) -> bytes:
        return os.pread(self.fd, size, offset)


def read_indexed_messages(
    path: Path | RandomAccess, wanted: Sequence[tuple[str, str]]
) -> list[tuple[int, int, bytes]] | None:
    """Return every message of the wanted channels, or None when the index cannot serve them.

    Args:
        path: an ``.mcap`` file, or its bytes read by position (an object in a bucket read
            with ranged requests: only the summary, the message indexes and the wanted
            messages are read).
        wanted: ``(topic, msgtype)`` pairs to read.

    Returns:
        ``(log_time_ns, index into wanted, data)`` per message, sorted by log time; or
        None: the file has no usable summary or chunk index, a chunk that holds a wanted
        message is compressed, or a record disagrees with the index.
    """
    if isinstance(path, HoldsMessages):
        held = path.held_messages(wanted)
        if held is not None:
            return held
    keys = {key: i for i, key in enumerate(wanted)}
    if not isinstance(path, str | os.PathLike):
        try:
            return _read(path, keys)
        except NOT_SERVABLE:
            return None
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        return _read(_LocalFile(fd), keys)
    except NOT_SERVABLE:
        return None
    finally:
        os.close(fd)


def index_serves(src: RandomAccess) -> bool:
    """Return whether :func:`read_indexed_messages` can serve any channel of this MCAP file.

    True when it has a summary with chunk indexes and stores every chunk uncompressed: then
    reading a few channels costs their message indexes and messages, not the file. Reads
    the footer and the summary only.
    """
    try:
        _, _, chunk_indexes = _read_summary(src)
    except NOT_SERVABLE:
        return False
    return bool(chunk_indexes) and not any(compression for *_, compression in chunk_indexes)


def _read(src: RandomAccess, wanted: dict[tuple[str, str], int]) -> list[tuple[int, int, bytes]]:
    schemas, channels, chunk_indexes = _read_summary(src)
    wanted_channels: dict[int, int] = {}
    for channel_id, (topic, schema_id, encoding) in channels.items():
        key = (topic, schemas.get(schema_id, ""))
        if key in wanted:
            if encoding != "cdr":
                raise _NotServableError
            wanted_channels[channel_id] = wanted[key]
    messages: list[tuple[int, int, bytes]] = []
    for first in range(0, len(chunk_indexes), _GROUP):
        group = chunk_indexes[first : first + _GROUP]
        messages.extend(_read_chunks(src, group, wanted_channels))
    messages.sort(key=lambda m: m[0])
    return messages


def _read_chunks(
    src: RandomAccess, chunk_indexes: Sequence[_ChunkIndex], wanted_channels: dict[int, int]
) -> list[tuple[int, int, bytes]]:
    """Return the wanted messages of these chunks (unsorted), in two rounds of reads.

    First one read per chunk: its wanted message index records and ``_SPILL`` bytes past
    them, the start of the next chunk, where a writer that closes a chunk after a large
    message (an image) has put the next small ones (tf). Then one read per run of messages
    that the first round did not already bring.
    """
    reads: list[tuple[int, int]] = []  # (offset, size), one per chunk with wanted messages
    records: list[tuple[int, int, int, int, int]] = []  # (read, offset, size, channel, base)
    for chunk_start, index_offsets, index_end, compression in chunk_indexes:
        offsets = [(cid, off) for cid, off in index_offsets.items() if cid in wanted_channels]
        if (offsets and compression) or index_end > src.size:
            raise _NotServableError
        if not offsets:
            continue
        # Chunk record: opcode, length, start, end, uncompressed size, crc, compression
        # string (empty here), records length; the records follow.
        records_start = chunk_start + 1 + 8 + 8 + 8 + 8 + 4 + 4 + 8
        # A channel's message index record ends where the chunk's next one starts.
        ends = sorted([*index_offsets.values(), index_end])
        spans = [(off, ends[bisect.bisect_right(ends, off)] - off, cid) for cid, off in offsets]
        low = min(off for off, _, _ in spans)
        high = max(off + size for off, size, _ in spans)
        reads.append((low, min(high + _SPILL, src.size) - low))
        records.extend((len(reads) - 1, off, size, cid, records_start) for off, size, cid in spans)
    blocks = list(_pread_many(src, [(size, offset) for offset, size in reads]))
    entries: list[tuple[int, int, int]] = []
    for k, offset, size, channel_id, records_start in records:
        at = offset - reads[k][0]
        entries.extend(
            (records_start + position, log_time, channel_id)
            for log_time, position in _message_index(blocks[k][at : at + size], channel_id)
        )
    entries.sort()
    held = sorted(range(len(reads)), key=lambda k: reads[k][0])
    held_starts = [reads[k][0] for k in held]
    runs = list(_runs(entries))
    run_blocks: list[bytes | None] = []
    missing: list[tuple[int, int]] = []  # (size, offset) of the runs not brought yet
    for run in runs:
        low, high = run[0][0], min(run[-1][0] + _FIRST_READ, src.size)
        i = bisect.bisect_right(held_starts, low) - 1
        k = held[i] if i >= 0 else -1
        if k >= 0 and high <= reads[k][0] + len(blocks[k]):
            run_blocks.append(blocks[k][low - reads[k][0] : high - reads[k][0]])
        else:
            run_blocks.append(None)
            missing.append((high - low, low))
    fetched = _pread_many(src, missing)
    messages: list[tuple[int, int, bytes]] = []
    for run, found in zip(runs, run_blocks, strict=True):
        block = found if found is not None else next(fetched)
        start = run[0][0]
        for position, log_time, channel_id in run:
            data = _message_data(
                src,
                block,
                at=position - start,
                position=position,
                channel_id=channel_id,
                log_time=log_time,
            )
            messages.append((log_time, wanted_channels[channel_id], data))
    return messages


def _runs(entries: list[tuple[int, int, int]]) -> Iterator[list[tuple[int, int, int]]]:
    """Group position-sorted entries into runs that one read covers."""
    run: list[tuple[int, int, int]] = []
    for entry in entries:
        if run and (
            entry[0] - run[-1][0] > _MAX_RUN_GAP or entry[0] + _FIRST_READ - run[0][0] > _MAX_RUN
        ):
            yield run
            run = []
        run.append(entry)
    if run:
        yield run


def _read_summary(
    src: RandomAccess,
) -> tuple[dict[int, str], dict[int, tuple[str, int, str]], list[_ChunkIndex]]:
    size = src.size
    if size < 2 * len(MAGIC) + _FOOTER_SIZE or src.pread(8, 0) != MAGIC:
        raise _NotServableError
    footer = src.pread(_FOOTER_SIZE, size - _FOOTER_SIZE)
    if footer[-8:] != MAGIC or footer[0] != OP_FOOTER:
        raise _NotServableError
    summary_start, summary_offset_start = struct.unpack_from("<QQ", footer, 9)
    summary_end = summary_offset_start or size - _FOOTER_SIZE
    if not 0 < summary_start < summary_end <= size - _FOOTER_SIZE:
        raise _NotServableError
    summary = src.pread(summary_end - summary_start, summary_start)
    schemas, channels, chunk_indexes = _parse_summary(summary)
    if not chunk_indexes:
        raise _NotServableError
    return schemas, channels, chunk_indexes


def _message_data(
    src: RandomAccess, block: bytes, *, at: int, position: int, channel_id: int, log_time: int
) -> bytes:
    """Return a message record's data from ``block`` (read more when it runs past it)."""
    opcode, length, record_channel, _, record_time, _ = _MESSAGE_HEAD.unpack_from(block, at)
    if opcode != OP_MESSAGE or record_channel != channel_id or record_time != log_time:
        raise _NotServableError
    data_size = length - 22
    if not 0 <= data_size <= src.size:  # a garbage length: no read of exabytes
        raise _NotServableError
    start = at + _MESSAGE_HEAD.size
    if start + data_size <= len(block):
        return block[start : start + data_size]
    data = src.pread(data_size, position + _MESSAGE_HEAD.size)
    if len(data) != data_size:
        raise _NotServableError
    return data


def _parse_summary(
    summary: bytes,
) -> tuple[dict[int, str], dict[int, tuple[str, int, str]], list[_ChunkIndex]]:
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, int, str]] = {}
    chunk_indexes: list[_ChunkIndex] = []
    pos = 0
    while pos < len(summary):
        opcode, length = RECORD_HEAD.unpack_from(summary, pos)
        body = pos + RECORD_HEAD.size
        pos = body + length
        if pos > len(summary):
            raise _NotServableError
        if opcode == OP_SCHEMA:
            schema_id, name = parse_schema(summary, body)
            schemas[schema_id] = name
        elif opcode == OP_CHANNEL:
            channel_id, channel = parse_channel(summary, body)
            channels[channel_id] = channel
        elif opcode == OP_CHUNK_INDEX:
            _, _, chunk_start, chunk_length = _CHUNK_INDEX_HEAD.unpack_from(summary, body)
            at = body + _CHUNK_INDEX_HEAD.size
            (map_size,) = _U32.unpack_from(summary, at)
            at += 4
            index_offsets = dict(struct.iter_unpack("<HQ", summary[at : at + map_size]))
            at += map_size
            (index_length,) = _U64.unpack_from(summary, at)
            compression, _ = _string(summary, at + 8)
            index_end = chunk_start + chunk_length + index_length
            if any(not chunk_start < o < index_end for o in index_offsets.values()):
                raise _NotServableError
            chunk_indexes.append((chunk_start, index_offsets, index_end, compression))
    return schemas, channels, chunk_indexes


def parse_schema(buffer: bytes, pos: int) -> tuple[int, str]:
    """Return ``(schema id, name)`` of the schema record whose body starts at ``pos``."""
    (schema_id,) = _U16.unpack_from(buffer, pos)
    return schema_id, _string(buffer, pos + 2)[0]


def parse_channel(buffer: bytes, pos: int) -> tuple[int, tuple[str, int, str]]:
    """Return ``(channel id, (topic, schema id, message encoding))`` of a channel record."""
    channel_id, schema_id = struct.unpack_from("<HH", buffer, pos)
    topic, at = _string(buffer, pos + 4)
    encoding, _ = _string(buffer, at)
    return channel_id, (topic, schema_id, encoding)


def _message_index(record: bytes, channel_id: int) -> list[tuple[int, int]]:
    """Return the ``(log time, offset in the chunk's records)`` pairs of a message index record."""
    if len(record) < 15:
        raise _NotServableError
    opcode, _ = RECORD_HEAD.unpack_from(record)
    (record_channel,) = _U16.unpack_from(record, 9)
    (size,) = _U32.unpack_from(record, 11)
    if opcode != OP_MESSAGE_INDEX or record_channel != channel_id or size % 16:
        raise _NotServableError
    if 15 + size > len(record):
        raise _NotServableError
    return list(struct.iter_unpack("<QQ", record[15 : 15 + size]))


def _string(buffer: bytes, pos: int) -> tuple[str, int]:
    (length,) = _U32.unpack_from(buffer, pos)
    end = pos + 4 + length
    if end > len(buffer):
        raise _NotServableError
    return buffer[pos + 4 : end].decode(), end
