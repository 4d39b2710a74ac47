"""Occupancy grid maps from a bag topic of ``nav_msgs/msg/OccupancyGrid`` (the last message).

A SLAM system publishes its map again and again as it grows; the last message is the map
it ended with. The message is returned as read; :mod:`loceval.maps.reading` checks its size
and turns its values into cell states.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Protocol, cast

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.errors import ReaderError
from loceval.readers.rosbag.bagfile import (
    deserialize,
    listing,
    normalize_msgtype,
    open_bag,
    raw_messages,
)
from loceval.readers.rosbag.messages import NS, HeaderLike, QuaternionLike

__all__ = ["GRID_MSGTYPE", "GridMessage", "read_grid_topic"]

GRID_MSGTYPE: Final = "nav_msgs/msg/OccupancyGrid"


@dataclass(frozen=True, slots=True, eq=False)
class GridMessage:
    """One ``nav_msgs/msg/OccupancyGrid`` as read (:mod:`loceval.maps.reading` checks it).

    Attributes:
        values: (N,) int8 cell values, -1 unknown, 0-100 occupancy percent, row-major.
        width: cells per row.
        height: rows.
        resolution_m: the cell size, metres.
        origin_xy: the grid origin in the map frame, metres.
        origin_yaw_rad: the grid's rotation, radians.
        stamp_ns: the header stamp.
        where: ``bag@topic`` for messages.
    """

    values: np.ndarray
    width: int
    height: int
    resolution_m: float
    origin_xy: FloatArray
    origin_yaw_rad: float
    stamp_ns: int
    where: str


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


def read_grid_topic(path: Path, topic: str) -> GridMessage:
    """Read the last ``nav_msgs/msg/OccupancyGrid`` message of a topic.

    Args:
        path: a bag (file, folder or zip, as for trajectories).
        topic: the map's topic (a ROS 1 topic with or without its leading slash).

    Raises:
        ReaderError: no such topic, another type or no message.
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
    q = info.origin.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    stamp = message.header.stamp
    return GridMessage(
        values=np.asarray(message.data, dtype=np.int8).reshape(-1),
        width=int(info.width),
        height=int(info.height),
        resolution_m=float(info.resolution),
        origin_xy=np.array([info.origin.position.x, info.origin.position.y], dtype=np.float64),
        origin_yaw_rad=yaw,
        stamp_ns=int(stamp.sec) * NS + int(stamp.nanosec),
        where=where,
    )
