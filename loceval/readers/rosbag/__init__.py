"""Read trajectories, tf trees and fixed offsets from ROS 1 and ROS 2 bags.

This package is the only place that imports rosbags: :mod:`.bagfile` opens bags and reads
raw messages, :mod:`.topics` reads pose topics, :mod:`.ranges` reads
``sensor_msgs/msg/Range`` topics (radio ranges), :mod:`.tf` reads the tf tree and chains,
and :mod:`.messages` holds the message shapes and results (it imports no rosbags).

It reads ROS 1 bags (one file or a split set), ROS 2 bags (a directory with
``metadata.yaml``; sqlite3 or MCAP storage; message or file compression), bare ``.mcap`` and
``.db3`` files, and zips of any of these, through ``rosbags.highlevel.AnyReader``. Message
types come from the definitions embedded in the bag, with ROS 2 Humble's as fallback for old
bags without them.

A trajectory is selected by a topic of a type in :data:`SUPPORTED_MSGTYPES` or by a tf
chain ``tf:PARENT:CHILD`` (composed by :mod:`loceval.readers.tftree`). Only the connections needed
are read and deserialized; image payloads are never decoded. Two shortcuts keep large
camera bags cheap: standard ``tf2_msgs/msg/TFMessage`` payloads in CDR are decoded by a
small struct-based parser instead of generic deserialization, and indexed, uncompressed
MCAP files are read through their message index (see :mod:`loceval.readers._mcap`), and
an MCAP file uploaded into object storage keeps its small messages from the upload's stream
(:mod:`.held`), so inspecting it reads none of them back.

Every rosbags error, and missing files, become :class:`~loceval.errors.ReaderError` here.
"""

from __future__ import annotations

import zipfile
from collections.abc import Sequence
from pathlib import Path

from rosbags.interfaces import Connection

from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError, ReaderError
from loceval.readers.rosbag.bagfile import (
    RemoteFile,
    is_tf,
    normalize_msgtype,
    open_bag,
    raw_messages,
    serves_by_index,
)
from loceval.readers.rosbag.held import HeldFile, HeldMessages, McapScan
from loceval.readers.rosbag.messages import (
    SUPPORTED_MSGTYPES,
    TF_MSGTYPE,
    BagFormat,
    BagOverview,
    PoseKind,
    StampSource,
    TopicOverview,
)
from loceval.readers.rosbag.ranges import RANGE_MSGTYPE, read_range_topic
from loceval.readers.rosbag.tf import parse_tf_selector, read_tf, read_tf_trajectory
from loceval.readers.rosbag.topics import pose_topic_overview, read_topic_trajectory
from loceval.readers.tftree import TfBuffer, compose_static_chain
from loceval.trajectory import Trajectory

__all__ = [
    "RANGE_MSGTYPE",
    "SUPPORTED_MSGTYPES",
    "TF_MSGTYPE",
    "BagFormat",
    "BagOverview",
    "HeldFile",
    "HeldMessages",
    "McapScan",
    "PoseKind",
    "RemoteFile",
    "StampSource",
    "TopicOverview",
    "is_bag_path",
    "read_bag_overview",
    "read_bag_static_transform",
    "read_bag_tf_buffer",
    "read_bag_trajectory",
    "read_range_topic",
    "serves_by_index",
]


def is_bag_path(path: Path) -> bool:
    """Whether ``path`` names something :func:`read_bag_trajectory` reads.

    True for a ``.bag``, ``.mcap`` or ``.db3`` file, a directory with a ``metadata.yaml``
    (a ROS 2 bag), a ``metadata.yaml`` file, and any ``.zip`` file (only bags are read from
    zips, and the bag reader's error lists what a zip without one holds). A path that does
    not exist counts by its suffix, so the reader reports it missing.
    """
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    if path.name == "metadata.yaml":
        return True
    suffix = path.suffix.lower()
    if suffix in {".bag", ".mcap", ".db3"}:
        return True
    if suffix == ".zip":
        return not path.exists() or zipfile.is_zipfile(path)
    return False


def read_bag_trajectory(
    path: Path | Sequence[Path] | RemoteFile,
    selector: str,
    *,
    stamp: StampSource = StampSource.HEADER,
    name: str = "",
    max_gap_ns: int | None = None,
) -> Trajectory:
    """Read one trajectory from a bag.

    Args:
        path: a bag (see :func:`is_bag_path`), the files of a split ROS 1 recording, or
            an MCAP file or ROS 1 bag read by position from a store (:class:`RemoteFile`).
        selector: a topic (``/amcl_pose``; a ROS 1 topic may be given with or without its
            leading slash when that is unambiguous) or a tf chain ``tf:PARENT:CHILD``.
        stamp: header stamps (default) or the bag's receive times.
        name: the trajectory's name; defaults to the selector.
        max_gap_ns: for tf chains, the longest interval between two samples of a dynamic
            link that is interpolated across; None for the per-link default of
            :mod:`loceval.readers.tftree` (max of 0.1 s and 3 median intervals).

    Returns:
        The trajectory; ``source`` is ``FILE@SELECTOR``, ``frame_id`` and
        ``child_frame_id`` name the frames (for tf chains ``PARENT`` and ``CHILD``).

    Raises:
        ReaderError: the bag is missing, damaged or not a bag; the topic or a frame is not
            in it (the message lists what is); the type holds no pose; the tf chain is
            broken; or fewer than three poses remain.
        InputError: ``stamp`` is neither ``header`` nor ``receive``.
    """
    stamp = _stamp_source(stamp)
    with open_bag(path) as bag:
        if selector.startswith("tf:"):
            parent, child = parse_tf_selector(selector)
            return read_tf_trajectory(
                bag, selector, parent, child, stamp=stamp, name=name, max_gap_ns=max_gap_ns
            )
        return read_topic_trajectory(bag, selector, stamp=stamp, name=name)


def read_bag_static_transform(
    path: Path | Sequence[Path], parent: str, child: str
) -> SimilarityTransform:
    """Return the fixed transform ``T_parent_child`` from a bag's static tf links.

    Used for the device offset when it is recorded on ``/tf_static`` (e.g. from a
    robot_state_publisher fed with the device's URDF).

    Args:
        path: a bag, or the files of a split ROS 1 recording.
        parent: the frame the transform maps into (e.g. the rigid body).
        child: the frame the transform maps from (e.g. the camera).

    Returns:
        The rigid transform: the pose of ``child`` in ``parent``.

    Raises:
        ReaderError: the bag cannot be read, a frame is unknown, the frames are not
            connected, or a link between them is dynamic.
    """
    with open_bag(path) as bag:
        buffer = read_tf(bag, stamp=StampSource.HEADER)
    if not buffer.links:
        msg = (
            f"Bag {bag.label!r} holds no tf data, so there is no static transform from "
            f"{parent!r} to {child!r}; give the device offset as a URDF instead."
        )
        raise ReaderError(msg)
    return compose_static_chain(buffer, parent, child)


def read_bag_tf_buffer(
    path: Path | Sequence[Path], *, stamp: StampSource = StampSource.HEADER
) -> TfBuffer:
    """Return all tf links of a bag (``/tf`` dynamic, ``/tf_static`` static).

    Args:
        path: a bag, or the files of a split ROS 1 recording.
        stamp: header stamps (default) or the bag's receive times.

    Raises:
        ReaderError: the bag cannot be read.
    """
    stamp = _stamp_source(stamp)
    with open_bag(path) as bag:
        return read_tf(bag, stamp=stamp)


def read_bag_overview(path: Path | Sequence[Path] | RemoteFile) -> BagOverview:
    """Summarize a bag: format, time range, topics, tf links and pose-topic time ranges.

    Reads the bag's index and metadata, the tf messages, and only the first and last
    message of each pose topic (the last one fully for a Path); other payloads (images,
    point clouds) are never read.

    Args:
        path: a bag, or the files of a split ROS 1 recording, or an MCAP file or ROS 1 bag
            read by position from a store (:class:`RemoteFile`: only what is listed above
            is fetched where the MCAP index allows).

    Raises:
        ReaderError: the bag cannot be read.
    """
    with open_bag(path) as bag:
        reader = bag.reader
        buffer = read_tf(bag, stamp=StampSource.HEADER)
        tf_topics = tuple(sorted({c.topic for c in reader.connections if is_tf(c)}))
        pose_conns = [
            c
            for c in reader.connections
            if normalize_msgtype(c.msgtype) in SUPPORTED_MSGTYPES and not is_tf(c)
        ]
        firsts: dict[str, tuple[Connection, bytes]] = {}
        lasts: dict[str, tuple[Connection, bytes]] = {}
        for conn, _, raw in raw_messages(bag, pose_conns):
            firsts.setdefault(conn.topic, (conn, raw))
            lasts[conn.topic] = (conn, raw)
        topics: list[TopicOverview] = []
        for topic, info in sorted(reader.topics.items()):
            msgtype = normalize_msgtype(info.msgtype or "")
            kind = SUPPORTED_MSGTYPES.get(msgtype)
            entry = TopicOverview(topic, msgtype, info.msgcount, kind)
            if kind is not None and kind is not PoseKind.TF and topic in lasts:
                entry = pose_topic_overview(bag, entry, firsts[topic], lasts[topic])
            topics.append(entry)
        empty = reader.message_count == 0
        return BagOverview(
            label=bag.label,
            storage_format=bag.storage_format,
            archive=bag.archive,
            start_ns=0 if empty else reader.start_time,
            end_ns=0 if empty else max(reader.end_time - 1, reader.start_time),
            message_count=reader.message_count,
            topics=tuple(topics),
            tf=buffer,
            tf_topics=tf_topics,
        )


def _stamp_source(stamp: StampSource | str) -> StampSource:
    try:
        return StampSource(stamp)
    except ValueError as err:
        msg = f"Unknown stamp source {stamp!r}; use 'header' or 'receive'."
        raise InputError(msg) from err
