"""Visits of control points marked in a bag: a topic whose messages announce arrivals.

Each message names the point the device has just reached: ``std_msgs/String`` in its
``data`` (stamped with the bag's receive time), ``geometry_msgs/PointStamped`` in its
``header.frame_id`` (stamped with the header, or the receive time). The device is taken to
stand on the point for the minimum stop duration after the arrival, so each message becomes
the visit ``[t, t + hold]``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final, Protocol, cast

import numpy as np

from loceval.controlpoints import ControlPoints, Visits
from loceval.errors import InputError, ReaderError
from loceval.readers.rosbag.bagfile import deserialize, normalize_msgtype, open_bag, raw_messages
from loceval.readers.rosbag.messages import HeaderLike, StampSource
from loceval.readers.rosbag.topics import match_topic

__all__ = ["ARRIVAL_MSGTYPES", "read_bag_arrivals"]

_STRING: Final = "std_msgs/msg/String"
_POINT: Final = "geometry_msgs/msg/PointStamped"
ARRIVAL_MSGTYPES: Final = (_STRING, _POINT)
"""The message types a topic of arrivals may have."""
_NS_PER_S: Final = 1_000_000_000


class _StringLike(Protocol):
    data: str


class _PointStampedLike(Protocol):
    header: HeaderLike


def read_bag_arrivals(
    path: Path,
    topic: str,
    points: ControlPoints,
    *,
    hold_s: float,
    stamp: StampSource = StampSource.HEADER,
) -> Visits:
    """Read the arrivals on ``topic`` as visits of ``points``.

    Args:
        path: the bag.
        topic: the topic of arrivals (String or PointStamped).
        points: the surveyed control points the messages name.
        hold_s: how long the device stands on the point after arriving, seconds.
        stamp: PointStamped: the header stamp (default) or the receive time.

    Returns:
        One visit per message, ``[t, t + hold_s]``.

    Raises:
        ReaderError: the bag or topic is missing, the topic's type announces no arrival,
            it has no message, or a message names a point that is not surveyed.
    """
    with open_bag(path) as bag:
        name = match_topic(bag, topic)
        conns = [c for c in bag.reader.connections if c.topic == name]
        msgtype = normalize_msgtype(conns[0].msgtype)
        if msgtype not in ARRIVAL_MSGTYPES:
            msg = (
                f"Topic {name!r} in bag {bag.label!r} is a {msgtype}; arrivals at control "
                "points are read from std_msgs/String (the id in data) or "
                "geometry_msgs/PointStamped (the id in header.frame_id)."
            )
            raise ReaderError(msg)
        ids: list[str] = []
        stamps: list[int] = []
        for conn, receive_ns, raw in raw_messages(bag, conns):  # one per arrival (tens)
            message = deserialize(bag, raw, conn.msgtype)
            if msgtype == _STRING:
                ids.append(cast("_StringLike", message).data.strip())
                stamps.append(receive_ns)
                continue
            header = cast("_PointStampedLike", message).header
            ids.append(header.frame_id.strip())
            header_ns = header.stamp.sec * _NS_PER_S + header.stamp.nanosec
            stamps.append(receive_ns if stamp is StampSource.RECEIVE else header_ns)
        if not ids:
            msg = f"Topic {name!r} in bag {bag.label!r} has no message; record the arrivals."
            raise ReaderError(msg)
        where = f"{bag.label}@{name}"
    try:
        index = points.index_of(ids, where=where)
    except InputError as err:
        raise ReaderError(str(err)) from err
    start = np.array(stamps, dtype=np.int64)
    order = np.argsort(start, kind="stable")
    hold_ns = round(hold_s * _NS_PER_S)
    return Visits(index[order], start[order], start[order] + hold_ns, source="bag")
