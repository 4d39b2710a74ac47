"""Keep an MCAP file's small messages while its bytes stream past, once, in order.

An upload into a bucket passes through the API once. Inspecting it afterwards reads its tf
and pose messages back out of the bucket through the index (:mod:`loceval.readers._mcap`):
in a camera bag, a ranged request per run of tf messages between two images, thousands of
round trips for a bag of a few GB. :class:`McapScan` is fed the upload's bytes as they
arrive and keeps the messages an inspection reads (tf and the pose types), each of at most
:data:`HELD_MESSAGE_BYTES`, up to :data:`HELD_BYTES` in all (when more arrive, the channel
that holds the most is let go and read from the file later); images and other payloads are
counted past, never copied. :class:`HeldFile` then serves the messages of the
channels it kept from memory and reads anything else where the file lies.

It holds messages only for the files the index reader would serve (a complete MCAP file
with chunk indexes, uncompressed chunks and no messages outside them), so what it returns
is what :func:`~loceval.readers._mcap.read_indexed_messages` would have read: every
message of the wanted channels, by log time, ties in file order. Anything else (another
format, compressed chunks, a record that does not fit its parent, a file cut short) makes
the scan give up and hold nothing; the file is then read the ordinary way. Record layouts
follow the MCAP specification (https://mcap.dev/spec).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable, Generator, Sequence
from typing import BinaryIO, Final

import numpy as np

from loceval.readers._mcap import (
    MAGIC,
    NOT_SERVABLE,
    OP_CHANNEL,
    OP_CHUNK,
    OP_CHUNK_INDEX,
    OP_FOOTER,
    OP_MESSAGE,
    OP_SCHEMA,
    RECORD_HEAD,
    ManyAtOnce,
    parse_channel,
    parse_schema,
)
from loceval.readers.rosbag.bagfile import RemoteFile, normalize_msgtype
from loceval.readers.rosbag.messages import SUPPORTED_MSGTYPES

__all__ = [
    "HELD_BYTES",
    "HELD_MESSAGE_BYTES",
    "HeldFile",
    "HeldMessages",
    "McapScan",
    "inspection_reads",
]

HELD_BYTES = 32 * 1024**2
"""The most message bytes (with a per-message allowance) one scan holds."""
HELD_MESSAGE_BYTES = 1024**2
"""A channel with a message larger than this is not held (an image, a point cloud)."""
_PER_MESSAGE = 64
"""Bytes counted per held message on top of its data: the list entry and its tuple."""
_MAX_DEFINITION = 4 * 1024**2
"""The largest schema or channel record read (a message definition is a few KB)."""
_MAX_COMPRESSION_NAME = 64

_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time
_CHUNK_HEAD = struct.Struct("<QQQII")  # start and end time, uncompressed size, crc, name length
_U64 = struct.Struct("<Q")

_SAVED_MAGIC: Final = b"LOCEVAL-HELD-1\n"
"""The first bytes of :meth:`HeldMessages.to_bytes` (its version: another is not read)."""
_SAVED_HEAD = struct.Struct("<I")  # the JSON head's length

_Request = Generator[int, bytes, None]
"""The parser: it yields ``n >= 0`` to take the next ``n`` bytes (sent back), ``-n`` to skip."""


class _UnusableError(Exception):
    """The bytes are no MCAP file the index reader would serve; hold nothing."""


def inspection_reads(msgtype: str) -> bool:
    """Whether an inspection reads the messages of this type: tf, and the pose types."""
    return normalize_msgtype(msgtype) in SUPPORTED_MSGTYPES


class HeldMessages:
    """The messages a scan held, by channel, with the file's schemas and channels.

    Attributes:
        schemas: schema id -> name (the message type, ``tf2_msgs/msg/TFMessage``).
        channels: channel id -> ``(topic, schema id, message encoding)``.
    """

    def __init__(
        self,
        schemas: dict[int, str],
        channels: dict[int, tuple[str, int, str]],
        held: dict[int, list[tuple[int, int, bytes]]],
        dropped: set[int],
    ) -> None:
        """Wrap what a finished scan found (see :meth:`McapScan.finish`)."""
        self.schemas = schemas
        self.channels = channels
        self._held = held
        self._dropped = dropped

    def messages(self, wanted: Sequence[tuple[str, str]]) -> list[tuple[int, int, bytes]] | None:
        """Return every message of the wanted channels, or None when one was not held.

        Args:
            wanted: ``(topic, msgtype)`` pairs.

        Returns:
            ``(log_time_ns, index into wanted, data)`` per message, sorted by log time
            (ties in file order), as :func:`~loceval.readers._mcap.read_indexed_messages`
            returns them; None when a wanted channel was let go or is not CDR-encoded.
        """
        keys = {key: i for i, key in enumerate(wanted)}
        found: list[tuple[int, int, int, bytes]] = []
        for channel_id, (topic, schema_id, encoding) in self.channels.items():
            index = keys.get((topic, self.schemas.get(schema_id, "")))
            if index is None:
                continue
            if encoding != "cdr" or channel_id in self._dropped:
                return None
            found.extend((t, seq, index, data) for t, seq, data in self._held.get(channel_id, ()))
        found.sort(key=lambda m: (m[0], m[1]))
        return [(t, index, data) for t, _, index, data in found]

    def to_bytes(self) -> bytes:
        """Return the held messages as bytes that :meth:`from_bytes` reads back.

        Stored beside an upload in a bucket, they let an evaluation take a camera bag's tf
        and poses in one request instead of a ranged read per run of them. Layout: a
        magic line, a JSON head (schemas, channels, dropped channels, each held channel's
        message count), then per held channel its log times and sequence numbers (u64), its
        message lengths (u32), and the messages' bytes, all little-endian.
        """
        channels = sorted(self._held)
        head = {
            "schemas": {str(k): v for k, v in self.schemas.items()},
            "channels": {str(k): list(v) for k, v in self.channels.items()},
            "dropped": sorted(self._dropped),
            "held": [[cid, len(self._held[cid])] for cid in channels],
        }
        encoded = json.dumps(head, separators=(",", ":")).encode()
        parts = [_SAVED_MAGIC, _SAVED_HEAD.pack(len(encoded)), encoded]
        for cid in channels:
            messages = self._held[cid]
            parts.append(np.array([m[0] for m in messages], dtype="<u8").tobytes())
            parts.append(np.array([m[1] for m in messages], dtype="<u8").tobytes())
            parts.append(np.array([len(m[2]) for m in messages], dtype="<u4").tobytes())
            parts.extend(m[2] for m in messages)
        return b"".join(parts)

    @classmethod
    def from_bytes(cls, data: bytes) -> HeldMessages:
        """Read what :meth:`to_bytes` wrote.

        Raises:
            ValueError: the bytes are not such a record (another version, cut short).
        """
        view = memoryview(data)
        start = len(_SAVED_MAGIC) + _SAVED_HEAD.size
        if bytes(view[: len(_SAVED_MAGIC)]) != _SAVED_MAGIC or len(data) < start:
            msg = "not a record of held MCAP messages (or another version of it)"
            raise ValueError(msg)
        (head_size,) = _SAVED_HEAD.unpack_from(view, len(_SAVED_MAGIC))
        try:
            head = json.loads(bytes(view[start : start + head_size]))
            schemas = {int(k): str(v) for k, v in head["schemas"].items()}
            channels = {
                int(k): (str(topic), int(schema), str(encoding))
                for k, (topic, schema, encoding) in head["channels"].items()
            }
            dropped = {int(c) for c in head["dropped"]}
            counts = [(int(cid), int(n)) for cid, n in head["held"]]
        except (KeyError, TypeError, ValueError) as err:
            msg = f"the head of the held MCAP messages is malformed ({err})"
            raise ValueError(msg) from None
        pos = start + head_size
        held: dict[int, list[tuple[int, int, bytes]]] = {}
        for cid, n in counts:
            if n < 0 or pos + 20 * n > len(data):
                msg = "the held MCAP messages are cut short"
                raise ValueError(msg)
            times = np.frombuffer(view, dtype="<u8", count=n, offset=pos)
            seqs = np.frombuffer(view, dtype="<u8", count=n, offset=pos + 8 * n)
            sizes = np.frombuffer(view, dtype="<u4", count=n, offset=pos + 16 * n)
            pos += 20 * n
            ends = pos + np.cumsum(sizes, dtype=np.int64)
            if n and int(ends[-1]) > len(data):
                msg = "the held MCAP messages are cut short"
                raise ValueError(msg)
            starts = ends - sizes
            held[cid] = [
                (t, q, bytes(view[a:b]))
                for t, q, a, b in zip(
                    times.tolist(), seqs.tolist(), starts.tolist(), ends.tolist(), strict=True
                )
            ]
            pos = int(ends[-1]) if n else pos
        if pos != len(data):
            msg = "the held MCAP messages have bytes past their end"
            raise ValueError(msg)
        return cls(schemas, channels, held, dropped)


class McapScan:
    """Fed an MCAP file's bytes in order, keeps its small messages (see the module doc)."""

    def __init__(
        self,
        *,
        keeps: Callable[[str], bool] = inspection_reads,
        held_bytes: int = HELD_BYTES,
    ) -> None:
        """Start before the file's first byte.

        Args:
            keeps: whether to hold the messages of a channel of this schema (message type);
                by default those an inspection reads (:func:`inspection_reads`). A message
                whose channel is not defined yet is held.
            held_bytes: the most held at once (see :data:`HELD_BYTES`).
        """
        self._keeps = keeps
        self._limit = held_bytes
        self._schemas: dict[int, str] = {}
        self._channels: dict[int, tuple[str, int, str]] = {}
        self._held: dict[int, list[tuple[int, int, bytes]]] = {}
        self._held_size: dict[int, int] = {}
        self._dropped: set[int] = set()
        self._total = 0
        self._seq = 0
        self._indexed = False
        self._complete = False
        self._usable = True
        self._parser: _Request | None = self._file()
        self._want = next(self._parser)
        self._buffer = bytearray()

    def feed(self, data: bytes | memoryview) -> None:
        """Take the file's next bytes."""
        if self._parser is None:
            if data and self._usable:  # bytes past the closing magic: not an MCAP file
                self._give_up()
            return
        view = memoryview(data)
        pos, end = 0, len(view)
        going = True
        while going:
            want = self._want
            if want < 0:  # skip: count the bytes past without keeping them
                step = min(-want, end - pos)
                pos += step
                self._want += step
                if self._want < 0:
                    return
                going = self._send(b"")
            elif self._buffer or end - pos < want:  # the piece ends inside the request
                step = min(want - len(self._buffer), end - pos)
                self._buffer += view[pos : pos + step]
                pos += step
                if len(self._buffer) < want:
                    return
                taken = bytes(self._buffer)
                self._buffer.clear()
                going = self._send(taken)
            else:
                pos += want
                going = self._send(bytes(view[pos - want : pos]))
        if pos < end and self._usable:
            self._give_up()

    def finish(self) -> HeldMessages | None:
        """Return what was held, or None: not a complete MCAP file the index would serve."""
        if not (self._usable and self._complete and self._indexed):
            return None
        return HeldMessages(self._schemas, self._channels, self._held, self._dropped)

    # -- the parser ------------------------------------------------------------------------

    def _send(self, taken: bytes) -> bool:
        """Hand the parser the bytes it asked for; return whether it asks for more."""
        if self._parser is None:
            return False
        try:
            self._want = self._parser.send(taken)
        except StopIteration:
            self._parser = None
        except (_UnusableError, *NOT_SERVABLE):  # the index reader's "unusable" too
            self._give_up()
        return self._parser is not None

    def _give_up(self) -> None:
        self._usable = False
        self._parser = None
        self._held.clear()
        self._buffer.clear()

    def _file(self) -> _Request:
        if (yield len(MAGIC)) != MAGIC:
            raise _UnusableError
        while True:
            opcode, length = RECORD_HEAD.unpack((yield RECORD_HEAD.size))
            if opcode == OP_CHUNK:
                yield from self._chunk(length)
            elif opcode in {OP_SCHEMA, OP_CHANNEL}:
                if length > _MAX_DEFINITION:
                    raise _UnusableError
                self._definition(opcode, (yield length))
            elif opcode == OP_MESSAGE:  # a message outside any chunk: no index serves it
                raise _UnusableError
            elif opcode == OP_FOOTER:
                yield -length
                if (yield len(MAGIC)) != MAGIC:
                    raise _UnusableError
                self._complete = True
                return
            else:
                self._indexed |= opcode == OP_CHUNK_INDEX
                yield -length

    def _chunk(self, length: int) -> _Request:
        head = yield _CHUNK_HEAD.size
        name_length = _CHUNK_HEAD.unpack(head)[4]
        if name_length > _MAX_COMPRESSION_NAME:
            raise _UnusableError
        if (yield name_length):  # compressed records: the index reader cannot serve them
            raise _UnusableError
        (rest,) = _U64.unpack((yield _U64.size))
        if rest != length - _CHUNK_HEAD.size - name_length - _U64.size:
            raise _UnusableError
        while rest > 0:
            opcode, size = RECORD_HEAD.unpack((yield RECORD_HEAD.size))
            rest -= RECORD_HEAD.size + size
            if rest < 0:
                raise _UnusableError
            if opcode == OP_MESSAGE:
                if size < _MESSAGE_HEAD.size:
                    raise _UnusableError
                channel_id, _, log_time, _ = _MESSAGE_HEAD.unpack((yield _MESSAGE_HEAD.size))
                size -= _MESSAGE_HEAD.size
                if self._holds(channel_id, size):
                    self._hold(channel_id, log_time, (yield size))
                else:
                    yield -size
            elif opcode in {OP_SCHEMA, OP_CHANNEL} and size <= _MAX_DEFINITION:
                self._definition(opcode, (yield size))
            else:
                yield -size

    def _definition(self, opcode: int, body: bytes) -> None:
        if opcode == OP_SCHEMA:
            schema_id, name = parse_schema(body, 0)
            self._schemas[schema_id] = name
        else:
            channel_id, channel = parse_channel(body, 0)
            self._channels[channel_id] = channel

    def _holds(self, channel_id: int, size: int) -> bool:
        if channel_id in self._dropped:
            return False
        channel = self._channels.get(channel_id)
        schema = None if channel is None else self._schemas.get(channel[1])
        if size > HELD_MESSAGE_BYTES or (schema is not None and not self._keeps(schema)):
            self._drop(channel_id)
            return False
        return True

    def _hold(self, channel_id: int, log_time: int, data: bytes) -> None:
        self._held.setdefault(channel_id, []).append((log_time, self._seq, data))
        self._seq += 1
        cost = len(data) + _PER_MESSAGE
        self._held_size[channel_id] = self._held_size.get(channel_id, 0) + cost
        self._total += cost
        while self._total > self._limit:
            self._drop(max(self._held_size, key=self._held_size.__getitem__))

    def _drop(self, channel_id: int) -> None:
        self._dropped.add(channel_id)
        self._held.pop(channel_id, None)
        self._total -= self._held_size.pop(channel_id, 0)


class HeldFile:
    """A bag file read where it lies, whose small messages were held while it streamed in.

    A :class:`~loceval.readers.rosbag.RemoteFile` (the file's bytes are read from it) with
    :meth:`held_messages`: the index reader takes the wanted channels' messages from memory
    when the scan held them all, and reads the file itself otherwise.
    """

    def __init__(self, file: RemoteFile, held: HeldMessages) -> None:
        """Serve ``file``'s bytes, and ``held``'s messages without reading them again."""
        self._file = file
        self._messages = held

    def held_messages(
        self, wanted: Sequence[tuple[str, str]]
    ) -> list[tuple[int, int, bytes]] | None:
        """See :meth:`HeldMessages.messages`."""
        return self._messages.messages(wanted)

    @property
    def size(self) -> int:
        """The file's size in bytes."""
        return self._file.size

    @property
    def name(self) -> str:
        """The file name."""
        return self._file.name

    @property
    def suffix(self) -> str:
        """The file name's suffix."""
        return self._file.suffix

    def exists(self) -> bool:
        """Whether the file exists."""
        return self._file.exists()

    def is_dir(self) -> bool:
        """False: a file."""
        return self._file.is_dir()

    def open(self, mode: str = "rb") -> BinaryIO:
        """Open the file itself for reading (rosbags' readers seek in it)."""
        return self._file.open(mode)

    def pread(self, size: int, offset: int) -> bytes:
        """Read ``size`` bytes at ``offset`` of the file."""
        return self._file.pread(size, offset)

    def pread_many(self, reads: Sequence[tuple[int, int]]) -> list[bytes]:
        """Read each ``(size, offset)`` of the file (at once, where it can)."""
        if isinstance(self._file, ManyAtOnce):
            return self._file.pread_many(reads)
        return [self._file.pread(size, offset) for size, offset in reads]
