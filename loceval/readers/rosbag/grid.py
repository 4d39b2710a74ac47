"""Occupancy grid maps from a bag topic of ``nav_msgs/msg/OccupancyGrid``: the last, or each.

A SLAM system publishes its map again and again as it grows; the last message is the map
it ended with; :func:`iter_grid_topic` yields each (at most a limit, evenly spread) for
the map's figures over time. Messages are returned as read; :mod:`loceval.maps.reading`
checks their size and turns their values into cell states.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Protocol, cast

import numpy as np
from numpy.typing import NDArray

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

__all__ = ["GRID_MSGTYPE", "GridMessage", "iter_grid_topic", "kept_indices", "read_grid_topic"]

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
    last = None
    for _, _, message in iter_grid_topic(path, topic, limit=1):
        last = message
    if last is None:  # pragma: no cover  (iter_grid_topic raises on an empty topic)
        msg = f"{path.name}@{topic}: the topic holds no map message."
        raise ReaderError(msg, option="map")
    return last


def kept_indices(total: int, limit: int) -> NDArray[np.intp]:
    """Return which of ``total`` messages are read: all, or ``limit`` evenly spread.

    The last message is always among them (it is the map the run ended with); with
    ``limit`` 1 it is the only one.
    """
    if total <= limit:
        return np.arange(total, dtype=np.intp)
    if limit <= 1:
        return np.array([total - 1], dtype=np.intp)
    return np.unique(np.rint(np.linspace(0, total - 1, limit)).astype(np.intp))


def iter_grid_topic(
    path: Path, topic: str, *, limit: int
) -> Iterator[tuple[int, int, GridMessage]]:
    """Yield the ``nav_msgs/msg/OccupancyGrid`` messages of a topic in receive order.

    Only the messages :func:`kept_indices` keeps are deserialized (one at a time: a
    caller that drops each before the next holds one map in memory).

    Args:
        path: a bag (file, folder or zip, as for trajectories).
        topic: the map's topic (a ROS 1 topic with or without its leading slash).
        limit: the most messages yielded; more are subsampled evenly, the last kept.

    Yields:
        ``(index, total, message)``: the message's position among the topic's ``total``.

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
        where = f"{bag.label}@{names[0]}"
        total = sum(c.msgcount for c in conns)
        if total == 0:
            msg = f"{where}: the topic holds no map message."
            raise ReaderError(msg, option="map")
        keep = set(kept_indices(total, limit).tolist())
        for index, (conn, _, raw) in enumerate(raw_messages(bag, conns)):  # one per message
            if index in keep:
                message = cast("_GridLike", deserialize(bag, raw, conn.msgtype))
                yield index, total, _grid_message(message, where)


def _grid_message(message: _GridLike, where: str) -> GridMessage:
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
