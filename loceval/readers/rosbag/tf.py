"""tf: the tree of a bag's ``/tf`` and ``/tf_static`` messages, and trajectories of chains.

Standard ``tf2_msgs/msg/TFMessage`` payloads in CDR are decoded by a small struct-based
parser (in bulk with numpy for messages of one layout) instead of generic deserialization.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Final, cast

import numpy as np
from numpy.typing import NDArray
from rosbags.typesys import TypesysError
from rosbags.typesys.store import Typestore

from loceval.core.arrays import FloatArray, IntArray, StampsNs
from loceval.errors import ReaderError
from loceval.readers._common import build_trajectory
from loceval.readers.rosbag.bagfile import (
    Bag,
    deserialize,
    is_static_topic,
    is_tf,
    listing,
    raw_messages,
)
from loceval.readers.rosbag.messages import NS, TF_MSGTYPE, StampSource, TFMessageLike
from loceval.readers.tftree import TfBuffer, TfLink, compose_chain, describe_chain, find_chain
from loceval.trajectory import MIN_POSES, Trajectory

__all__ = ["parse_tf_selector", "read_tf", "read_tf_trajectory"]


def parse_tf_selector(selector: str) -> tuple[str, str]:
    """Return ``(PARENT, CHILD)`` of a ``tf:PARENT:CHILD`` selector."""
    parts = selector.split(":")
    if len(parts) != 3 or not parts[1].strip("/") or not parts[2].strip("/"):
        msg = (
            f"tf selector {selector!r} is malformed; type tf:PARENT:CHILD, for example "
            "tf:map:base_link."
        )
        raise ReaderError(msg)
    return parts[1].strip().lstrip("/"), parts[2].strip().lstrip("/")


def read_tf_trajectory(
    bag: Bag,
    selector: str,
    parent: str,
    child: str,
    *,
    stamp: StampSource,
    name: str,
    max_gap_ns: int | None,
) -> Trajectory:
    """Read the trajectory of the tf chain from ``parent`` to ``child``."""
    where = f"{bag.label}@{selector}"
    buffer = read_tf(bag, stamp=stamp)
    if not buffer.links:
        topics = listing(sorted(bag.reader.topics))
        msg = (
            f"Bag {bag.label!r} holds no tf messages (topics: {topics or 'none'}); select a "
            "pose topic instead of a tf chain."
        )
        raise ReaderError(msg)
    steps = find_chain(buffer, parent, child)
    chain = compose_chain(buffer, parent, child, max_gap_ns=max_gap_ns)
    total = chain.stamps_ns.shape[0] + chain.dropped
    if chain.stamps_ns.shape[0] < MIN_POSES:
        ranges = "; ".join(
            f"{s.link.name} {s.link.stamps_ns[0] / NS:.3f}..{s.link.stamps_ns[-1] / NS:.3f} s"
            for s in steps
            if not s.link.is_static
        )
        msg = (
            f"{where}: only {chain.stamps_ns.shape[0]} of {total} poses of the chain "
            f"{describe_chain(steps)!r} have data on every link (time ranges: {ranges}); "
            "check that the links overlap in time, or allow a larger max gap."
        )
        raise ReaderError(msg)
    notes = [f"{where}: tf chain {describe_chain(steps)}."]
    notes.extend(
        f"{where}: {s.link.invalid_count} samples of tf link {s.link.name} held NaN, inf or "
        "a zero quaternion and were dropped."
        for s in steps
        if s.link.invalid_count
    )
    if chain.dropped:
        notes.append(
            f"{where}: {chain.dropped} of {total} poses dropped where a link of the chain "
            "had no data (outside its time range or in a gap longer than its max gap)."
        )
    return build_trajectory(
        chain.stamps_ns,
        chain.positions_xyz,
        chain.quat_xyzw,
        where=where,
        name=name or selector,
        source=where,
        frame_id=parent,
        child_frame_id=child,
        warnings=tuple(notes),
    )


_TF_RIHS01: Final = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
"""Type hash of the standard tf2_msgs/msg/TFMessage (the layout :func:`_tf_cdr_layout` knows)."""

_TfKey = tuple[str | bytes, str | bytes, bool]
"""(parent, child, static): frame ids as bytes from the CDR parser, str from rosbags."""


def read_tf(bag: Bag, *, stamp: StampSource) -> TfBuffer:
    """Read every tf link of a bag (``/tf`` dynamic, ``/tf_static`` static)."""
    conns = [c for c in bag.reader.connections if is_tf(c)]
    collector = _TfCollector(
        receive=stamp is StampSource.RECEIVE,
        cdr=bag.reader.is2 and _standard_tf_layout(bag.reader.typestore),
    )
    with _damaged_tf(bag.label):
        for conn, receive_ns, raw in raw_messages(bag, conns):
            static = is_static_topic(conn.topic)
            if not collector.add_raw(raw, receive_ns, static=static):
                tf_msg = cast("TFMessageLike", deserialize(bag, raw, conn.msgtype))
                collector.add_message(tf_msg, receive_ns, static=static)
        samples = collector.finish()
    return _build_buffer(samples, label=bag.label)


@contextmanager
def _damaged_tf(label: str) -> Iterator[None]:
    """Report tf messages the CDR parser finds cut short as a damaged bag."""
    try:
        yield
    except struct.error as err:
        msg = (
            f"Bag {label!r} looks damaged: a tf message is cut short ({err}); re-copy the "
            "file or record it again."
        )
        raise ReaderError(msg) from err


class _LinkSamples:
    """Samples of one link: Python lists (one message at a time) and numpy blocks."""

    __slots__ = ("blocks", "seqs", "stamps", "values")

    def __init__(self) -> None:
        self.seqs: list[int] = []
        self.stamps: list[int] = []
        self.values: list[float] = []
        self.blocks: list[tuple[StampsNs, StampsNs, FloatArray]] = []

    def arrays(self) -> tuple[StampsNs, StampsNs, FloatArray]:
        """Return (M,) message sequence numbers, (M,) stamps, (M, 7) values, by sequence."""
        seqs = np.concatenate([np.array(self.seqs, dtype=np.int64), *(b[0] for b in self.blocks)])
        stamps = np.concatenate(
            [np.array(self.stamps, dtype=np.int64), *(b[1] for b in self.blocks)]
        )
        values = np.concatenate(
            [np.array(self.values, dtype=np.float64).reshape(-1, 7), *(b[2] for b in self.blocks)]
        )
        order = np.argsort(seqs, kind="stable")
        return seqs[order], stamps[order], values[order]


class _TfCollector:
    """Collect tf samples per link, decoding standard CDR TFMessages in bulk.

    Dynamic CDR messages are queued by byte length; messages of one length from one
    publisher share their layout (same frame ids), so :meth:`finish` decodes each group
    with numpy after checking that every message matches the first one's non-numeric
    bytes. Messages that differ are decoded one by one.
    """

    def __init__(self, *, receive: bool, cdr: bool) -> None:
        self.samples: dict[_TfKey, _LinkSamples] = {}
        self._receive = receive
        self._cdr = cdr
        self._seq = 0
        self._pending: dict[int, tuple[list[bytes], list[int], list[int]]] = {}

    def _link(self, key: _TfKey) -> _LinkSamples:
        link = self.samples.get(key)
        if link is None:
            link = self.samples[key] = _LinkSamples()
        return link

    def add_raw(self, raw: bytes, receive_ns: int, *, static: bool) -> bool:
        """Take a raw CDR message; False when it needs generic deserialization."""
        if not self._cdr or raw[0:2] != b"\x00\x01":
            return False
        self._seq += 1
        if static:
            self._add_one(raw, receive_ns, self._seq, static=True)
            return True
        group = self._pending.get(len(raw))
        if group is None:
            group = self._pending[len(raw)] = ([], [], [])
        group[0].append(raw)
        group[1].append(receive_ns)
        group[2].append(self._seq)
        return True

    def add_message(self, tf_msg: TFMessageLike, receive_ns: int, *, static: bool) -> None:
        """Take a deserialized TFMessage."""
        self._seq += 1
        for tr in tf_msg.transforms:
            link = self._link((tr.header.frame_id, tr.child_frame_id, static))
            st = tr.header.stamp
            link.seqs.append(self._seq)
            link.stamps.append(receive_ns if self._receive else st.sec * NS + st.nanosec)
            t, q = tr.transform.translation, tr.transform.rotation
            link.values.extend((t.x, t.y, t.z, q.x, q.y, q.z, q.w))

    def finish(self) -> dict[_TfKey, _LinkSamples]:
        """Decode the queued messages and return the samples per link."""
        for raws, receives, seqs in self._pending.values():
            self._add_group(raws, receives, seqs)
        self._pending.clear()
        return self.samples

    def _add_one(self, raw: bytes, receive_ns: int, seq: int, *, static: bool) -> None:
        layout, _ = _tf_cdr_layout(raw)
        for stamp_at, parent, child, values_at in layout:
            link = self._link((parent, child, static))
            sec, nanosec = _STAMP(raw, stamp_at)
            link.seqs.append(seq)
            link.stamps.append(receive_ns if self._receive else sec * NS + nanosec)
            link.values.extend(_SEVEN_DOUBLES(raw, values_at))

    def _add_group(self, raws: list[bytes], receives: list[int], seqs: list[int]) -> None:
        layout, fixed = _tf_cdr_layout(raws[0])
        table = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), -1)
        same = (table[:, fixed] == table[0, fixed]).all(axis=1)
        for i in np.flatnonzero(~same).tolist():
            self._add_one(raws[i], receives[i], seqs[i], static=False)
        rows = table[same]
        seq_block = np.array(seqs, dtype=np.int64)[same]
        receive_block = np.array(receives, dtype=np.int64)[same]
        for stamp_at, parent, child, values_at in layout:
            if self._receive:
                stamps = receive_block
            else:
                sec = _column(rows, stamp_at, "<i4")
                nanosec = _column(rows, stamp_at + 4, "<u4")
                stamps = sec.astype(np.int64) * NS + nanosec.astype(np.int64)
            values = np.ascontiguousarray(rows[:, values_at : values_at + 56]).view("<f8")
            self._link((parent, child, False)).blocks.append((seq_block, stamps, values))


def _column(rows: NDArray[np.uint8], at: int, dtype: str) -> NDArray[np.generic]:
    """Return the 4-byte little-endian field at byte ``at`` of every row."""
    out: NDArray[np.generic] = np.ascontiguousarray(rows[:, at : at + 4]).view(dtype)[:, 0]
    return out


_U32 = struct.Struct("<I").unpack_from
_STAMP = struct.Struct("<iI").unpack_from
_SEVEN_DOUBLES = struct.Struct("<7d").unpack_from


def _tf_cdr_layout(raw: bytes) -> tuple[list[tuple[int, bytes, bytes, int]], IntArray]:
    """Locate the fields of a little-endian CDR tf2_msgs/msg/TFMessage.

    Layout after the 4-byte encapsulation header (CDR alignment is relative to its end):
    uint32 count; per transform: int32 sec, uint32 nanosec, string frame_id, string
    child_frame_id (uint32 length counting the NUL, bytes; 4-aligned), then seven float64
    (8-aligned): translation x y z, rotation x y z w.

    Returns:
        Per transform ``(stamp offset, parent, child, values offset)``, and the byte
        offsets that are not stamps or values (count, string lengths, strings, padding).

    Raises:
        struct.error: the message is cut short.
    """
    (count,) = _U32(raw, 4)
    layout: list[tuple[int, bytes, bytes, int]] = []
    fixed: list[range] = [range(4, 8)]
    pos = 8
    for _ in range(count):
        stamp_at = pos
        (length,) = _U32(raw, pos + 8)
        start = pos + 12
        parent = raw[start : start + length - 1]
        pos = start + length
        pos += -(pos - 4) % 4
        (length,) = _U32(raw, pos)
        child = raw[pos + 4 : pos + 3 + length]
        pos += 4 + length
        pos += -(pos - 4) % 8
        _SEVEN_DOUBLES(raw, pos)  # raises struct.error when cut short
        fixed.append(range(stamp_at + 8, pos))
        layout.append((stamp_at, parent, child, pos))
        pos += 56
    fixed.append(range(pos, len(raw)))
    return layout, np.fromiter((i for r in fixed for i in r), dtype=np.intp)


def _build_buffer(samples: Mapping[_TfKey, _LinkSamples], *, label: str) -> TfBuffer:
    # Frame ids are compared without a leading slash (tf2 strips it; ROS 1 tf kept it).
    merged: dict[tuple[str, str], dict[bool, list[_LinkSamples]]] = {}
    for (parent, child, static), link in samples.items():
        pair = (_frame_name(parent, label=label), _frame_name(child, label=label))
        merged.setdefault(pair, {}).setdefault(static, []).append(link)
    links: list[TfLink] = []
    for (parent, child), by_static in sorted(merged.items()):
        # A pair published on /tf counts as dynamic; its /tf_static samples are ignored.
        static = False not in by_static
        parts = [p.arrays() for p in by_static[static]]
        seqs = np.concatenate([p[0] for p in parts])
        order = np.argsort(seqs, kind="stable")
        stamps = np.concatenate([p[1] for p in parts])[order]
        values = np.concatenate([p[2] for p in parts])[order]
        count = int(stamps.shape[0])
        if static:
            # The last static message wins (receive order), whatever its stamp.
            stamps, values = stamps[-1:], values[-1:]
        links.append(
            TfLink(
                parent,
                child,
                stamps,
                values[:, :3],
                values[:, 3:],
                is_static=static,
                message_count=count,
            )
        )
    return TfBuffer(tuple(links))


def _frame_name(raw: str | bytes, *, label: str) -> str:
    if isinstance(raw, str):
        return raw.lstrip("/")
    try:
        return raw.decode().lstrip("/")
    except UnicodeDecodeError as err:
        msg = f"Bag {label!r} holds a tf frame id {raw!r} that is not UTF-8; fix the publisher."
        raise ReaderError(msg) from err


def _standard_tf_layout(typestore: Typestore) -> bool:
    """Whether the bag's TFMessage definition is the standard one the CDR parser knows."""
    try:
        return typestore.hash_rihs01(TF_MSGTYPE) == _TF_RIHS01
    except (KeyError, TypesysError):
        return False
