"""Occupancy grid maps from a bag topic of ``nav_msgs/msg/OccupancyGrid`` (the last message).

A SLAM system publishes its map again and again as it grows; the last message is the map
it ended with. Cell values are ROS's: -1 unknown, 0-100 the occupancy probability in
percent; a cell is occupied from 65 and free up to 19.6, as map_server saves them
(``occupied_thresh: 0.65``, ``free_thresh: 0.196``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Final, Protocol, cast

import numpy as np

from loceval.errors import ReaderError
from loceval.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, check_map_size
from loceval.readers.rosbag.bagfile import (
    deserialize,
    listing,
    normalize_msgtype,
    open_bag,
    raw_messages,
)
from loceval.readers.rosbag.messages import NS, HeaderLike, QuaternionLike

__all__ = ["GRID_MSGTYPE", "read_grid_topic"]

GRID_MSGTYPE: Final = "nav_msgs/msg/OccupancyGrid"
_OCCUPIED_PCT: Final = 65
_FREE_PCT: Final = 19.6


class _PointLike(Protocol):
    x: float
    y: float


class _PoseLike(Protocol):
    position: _PointLike
    orientation: QuaternionLike


class _InfoLike(Protocol):
    resolution: float
    width: int
    height: int
    origin: _PoseLike


class _GridLike(Protocol):
    header: HeaderLike
    info: _InfoLike
    data: np.ndarray


def read_grid_topic(path: Path, topic: str) -> OccupancyGrid:
    """Read the last ``nav_msgs/msg/OccupancyGrid`` message of a topic.

    Args:
        path: a bag (file, folder or zip, as for trajectories).
        topic: the map's topic (a ROS 1 topic with or without its leading slash).

    Raises:
        ReaderError: no such topic, another type, no message, or data that do not match
            the declared width and height.
        InputError: the declared size is over the limit.
    """
    with open_bag(path) as bag:
        topics = bag.reader.topics
        names = [t for t in topics if t == topic or t.lstrip("/") == topic.lstrip("/")]
        if len(names) != 1:
            grids = [
                t
                for t, info in topics.items()
                if normalize_msgtype(info.msgtype or "") == GRID_MSGTYPE
            ]
            msg = (
                f"Topic {topic!r} is not in bag {bag.label!r}; its {GRID_MSGTYPE} topics: "
                f"{listing(sorted(grids)) or 'none'}; name one of them."
            )
            raise ReaderError(msg, option="map")
        conns = [c for c in bag.reader.connections if c.topic == names[0]]
        types = sorted({normalize_msgtype(c.msgtype) for c in conns})
        if types != [GRID_MSGTYPE]:
            msg = (
                f"Topic {names[0]!r} in bag {bag.label!r} has type {', '.join(types)}, not "
                f"{GRID_MSGTYPE}; name the map's topic."
            )
            raise ReaderError(msg, option="map")
        last: tuple[int, bytes, str] | None = None
        for conn, receive_ns, raw in raw_messages(bag, conns):
            if last is None or receive_ns >= last[0]:
                last = (receive_ns, raw, conn.msgtype)
        if last is None:
            msg = f"{bag.label}@{names[0]}: the topic holds no map message."
            raise ReaderError(msg, option="map")
        where = f"{bag.label}@{names[0]}"
        message = cast("_GridLike", deserialize(bag, last[1], last[2]))
    info = message.info
    width, height = int(info.width), int(info.height)
    check_map_size(width, height, where=where)
    data = np.asarray(message.data, dtype=np.int8).reshape(-1)
    if data.size != width * height:
        msg = (
            f"{where}: the map declares {width} x {height} cells but holds {data.size} values; "
            "the message is damaged."
        )
        raise ReaderError(msg, option="map")
    values = data.reshape(height, width)
    states = np.full(values.shape, UNKNOWN, dtype=np.int8)
    states[values >= _OCCUPIED_PCT] = OCCUPIED
    states[(values >= 0) & (values <= _FREE_PCT)] = FREE
    q = info.origin.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    stamp = message.header.stamp
    return OccupancyGrid(
        states,
        float(info.resolution),
        (float(info.origin.position.x), float(info.origin.position.y)),
        yaw,
        source=where,
        stamp_ns=int(stamp.sec) * NS + int(stamp.nanosec),
    )
