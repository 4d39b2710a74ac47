"""Range measurements from a bag topic of ``sensor_msgs/msg/Range``.

Each message is one range from the tag to the anchor its ``header.frame_id`` names (the
anchors file's id, as written). Messages whose range is NaN, infinite or negative, or
whose frame id is no anchor, are dropped, counted per reason and named in one warning, as
the CSV reader does (:func:`loceval.readers.radio.read_ranges`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Final, Protocol, cast

import numpy as np

from loceval.errors import ReaderError
from loceval.readers.radio import Anchors, Ranges
from loceval.readers.rosbag.bagfile import (
    deserialize,
    listing,
    normalize_msgtype,
    open_bag,
    raw_messages,
)
from loceval.readers.rosbag.messages import NS, HeaderLike, StampSource

__all__ = ["RANGE_MSGTYPE", "read_range_topic"]

RANGE_MSGTYPE: Final = "sensor_msgs/msg/Range"
_NAMED_IDS: Final = 3


class _RangeLike(Protocol):
    header: HeaderLike
    range: float


def read_range_topic(
    path: Path, topic: str, anchors: Anchors, *, stamp: StampSource = StampSource.HEADER
) -> Ranges:
    """Read the ranges of one ``sensor_msgs/msg/Range`` topic.

    Args:
        path: a bag (file, folder or zip, as for trajectories).
        topic: the topic (a ROS 1 topic with or without its leading slash).
        anchors: the anchors whose ids the messages' frame ids name.
        stamp: header stamps (default) or the bag's receive times.

    Returns:
        The usable ranges sorted by time, with a warning naming the dropped messages.

    Raises:
        ReaderError: the bag cannot be read, has no such topic, the topic is of another
            type, or no message is usable.
    """
    with open_bag(path) as bag:
        topics = bag.reader.topics
        names = (
            [topic]
            if topic in topics
            else [t for t in topics if t.lstrip("/") == topic.lstrip("/")]
        )
        where = f"{bag.label}@{topic}"
        if len(names) != 1:
            ranged = [
                t
                for t, info in topics.items()
                if normalize_msgtype(info.msgtype or "") == RANGE_MSGTYPE
            ]
            msg = (
                f"Topic {topic!r} is not in bag {bag.label!r}; its {RANGE_MSGTYPE} topics: "
                f"{listing(sorted(ranged)) or 'none'}; name one of them."
            )
            raise ReaderError(msg)
        conns = [c for c in bag.reader.connections if c.topic == names[0]]
        types = sorted({normalize_msgtype(c.msgtype) for c in conns})
        if types != [RANGE_MSGTYPE]:
            msg = (
                f"Topic {names[0]!r} in bag {bag.label!r} has type {', '.join(types)}, not "
                f"{RANGE_MSGTYPE}; name a topic of range measurements."
            )
            raise ReaderError(msg)
        stamps: list[int] = []
        frames: list[str] = []
        values: list[float] = []
        for conn, receive_ns, raw in raw_messages(bag, conns):
            message = cast("_RangeLike", deserialize(bag, raw, conn.msgtype))
            header = message.header
            stamps.append(
                receive_ns
                if stamp is StampSource.RECEIVE
                else header.stamp.sec * NS + header.stamp.nanosec
            )
            frames.append(header.frame_id)
            values.append(float(message.range))
    return _ranges(stamps, frames, values, anchors, where=where)


def _ranges(
    stamps: list[int], frames: list[str], values: list[float], anchors: Anchors, *, where: str
) -> Ranges:
    total = len(values)
    if not total:
        msg = f"{where}: the topic holds no message; check that the bag recorded the ranges."
        raise ReaderError(msg)
    known = {anchor_id: k for k, anchor_id in enumerate(anchors.ids)}
    index = np.fromiter((known.get(f, -1) for f in frames), dtype=np.intp, count=total)
    range_m = np.array(values, dtype=np.float64)
    bad = ~np.isfinite(range_m)
    negative = ~bad & (range_m < 0)
    unknown = ~bad & ~negative & (index < 0)
    keep = ~(bad | negative | unknown)
    notes: list[str] = []
    if not keep.all():
        parts = [
            f"{count} {why}"
            for count, why in (
                (int(bad.sum()), "whose range is NaN or infinite"),
                (int(negative.sum()), "with a negative range"),
                (int(unknown.sum()), "whose frame id is no anchor id"),
            )
            if count
        ]
        ids = sorted({frames[k] for k in np.flatnonzero(unknown)})
        if ids:
            quoted = ", ".join(repr(i) for i in ids[:_NAMED_IDS])
            more = f" and {len(ids) - _NAMED_IDS} more" if len(ids) > _NAMED_IDS else ""
            parts[-1] += f" ({quoted}{more})"
        notes.append(
            f"{where}: {total - int(keep.sum())} of {total} range messages dropped: "
            f"{'; '.join(parts)}."
        )
    if not keep.any():
        msg = (
            f"{where}: none of the {total} range messages is usable ({'; '.join(notes)}); "
            "check that the frame ids name the anchors of the anchors file."
        )
        raise ReaderError(msg)
    stamps_ns = np.array(stamps, dtype=np.int64)[keep]
    order = np.argsort(stamps_ns, kind="stable")
    return Ranges(
        anchors=anchors,
        stamps_ns=stamps_ns[order],
        anchor_index=index[keep][order],
        range_m=range_m[keep][order],
        source=where,
        warnings=tuple(notes),
    )
