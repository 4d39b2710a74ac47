"""Read trajectories, tf trees and fixed offsets from ROS 1 and ROS 2 bags.

This is the only module that imports rosbags. It reads ROS 1 bags (one file or a split
set), ROS 2 bags (a directory with ``metadata.yaml``; sqlite3 or MCAP storage; message or
file compression), bare ``.mcap`` and ``.db3`` files, and zips of any of these, through
``rosbags.highlevel.AnyReader``. Message types come from the definitions embedded in the
bag, with ROS 2 Humble's as fallback for old bags without them.

A trajectory is selected by a topic of a type in :data:`SUPPORTED_MSGTYPES` or by a tf
chain ``tf:PARENT:CHILD`` (composed by :mod:`loceval.tftree`). Only the connections needed
are read and deserialized; image payloads are never decoded. Two shortcuts keep large
camera bags cheap: standard ``tf2_msgs/msg/TFMessage`` payloads in CDR are decoded by a
small struct-based parser instead of generic deserialization, and indexed, uncompressed
MCAP files are read through their message index (see :mod:`loceval.readers._mcap`).

Every rosbags error, and missing files, become :class:`~loceval.errors.ReaderError` here.
"""

from __future__ import annotations

import os
import sqlite3
import struct
import sys
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from types import MappingProxyType
from typing import Final, Protocol, cast

import numpy as np
from numpy.typing import NDArray
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.rosbag1 import ReaderError as Rosbag1ReaderError
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, TypesysError, get_typestore
from rosbags.typesys.store import Typestore

if sys.version_info >= (3, 14):
    from compression.zstd import ZstdError
else:  # rosbags depends on backports.zstd before Python 3.14
    from backports.zstd import ZstdError

from loceval._typing import FloatArray, IntArray, StampsNs
from loceval.errors import InputError, ReaderError
from loceval.geometry import SimilarityTransform
from loceval.readers._archive import extracted_bag
from loceval.readers._common import build_trajectory
from loceval.readers._mcap import read_indexed_messages
from loceval.tftree import TfBuffer, TfLink, compose_chain, compose_static_chain, describe_chain
from loceval.tftree import find_chain as _find_chain
from loceval.trajectory import MIN_POSES, Trajectory

__all__ = [
    "SUPPORTED_MSGTYPES",
    "TF_MSGTYPE",
    "BagFormat",
    "BagOverview",
    "PoseKind",
    "StampSource",
    "TopicOverview",
    "is_bag_path",
    "read_bag_overview",
    "read_bag_static_transform",
    "read_bag_tf_buffer",
    "read_bag_trajectory",
]

_NS = 1_000_000_000
_MAX_LISTED = 40


class StampSource(StrEnum):
    """Which time stamps a pose gets."""

    HEADER = "header"
    """``header.stamp`` of the message (of the transform, for tf): when it was measured."""
    RECEIVE = "receive"
    """The bag's receive (log) time: when the recorder got it."""


class PoseKind(StrEnum):
    """How a supported message type carries a pose."""

    POSE = "pose"
    POSE_WITH_COVARIANCE = "pose_with_covariance"
    TRANSFORM = "transform"
    POINT = "point"
    ODOMETRY = "odometry"
    PATH = "path"
    TF = "tf"


class BagFormat(StrEnum):
    """Storage format of a bag."""

    ROSBAG1 = "rosbag1"
    ROSBAG2_SQLITE3 = "rosbag2-sqlite3"
    ROSBAG2_MCAP = "rosbag2-mcap"


TF_MSGTYPE: Final = "tf2_msgs/msg/TFMessage"

SUPPORTED_MSGTYPES: Final[Mapping[str, PoseKind]] = MappingProxyType(
    {
        "geometry_msgs/msg/PoseStamped": PoseKind.POSE,
        "geometry_msgs/msg/PoseWithCovarianceStamped": PoseKind.POSE_WITH_COVARIANCE,
        "geometry_msgs/msg/TransformStamped": PoseKind.TRANSFORM,
        "geometry_msgs/msg/PointStamped": PoseKind.POINT,
        "nav_msgs/msg/Odometry": PoseKind.ODOMETRY,
        "nav_msgs/msg/Path": PoseKind.PATH,
        TF_MSGTYPE: PoseKind.TF,
    }
)
"""Message types that hold poses (ROS 1 names are normalized to this ``pkg/msg/Type`` form).

A Path yields the poses of its last message, stamped by each pose's header. TFMessage
topics are read as a tf tree (``tf:PARENT:CHILD``); topics named ``tf_static`` hold static
links.
"""

# rosbags reports damaged files through its own errors, and through these builtins when a
# record is cut short or garbled (struct unpacking, text decoding, sqlite, decompressors).
_FOREIGN_ERRORS: Final = (
    AnyReaderError,
    Rosbag1ReaderError,
    Rosbag2ReaderError,
    SerdeError,
    TypesysError,
    sqlite3.Error,
    ZstdError,
    struct.error,
    EOFError,
    OSError,
    ValueError,
    RuntimeError,
    KeyError,
    IndexError,
    AssertionError,
    TypeError,  # rosbags' MCAP reader calls ord() on an empty read of a truncated file
)


# --- Shapes of the deserialized messages (rosbags builds dataclasses with these fields).


class _Time(Protocol):
    sec: int
    nanosec: int


class _Header(Protocol):
    stamp: _Time
    frame_id: str


class _Vector3(Protocol):
    x: float
    y: float
    z: float


class _Quaternion(Protocol):
    x: float
    y: float
    z: float
    w: float


class _Pose(Protocol):
    position: _Vector3
    orientation: _Quaternion


class _PoseWithCovariance(Protocol):
    pose: _Pose


class _Transform(Protocol):
    translation: _Vector3
    rotation: _Quaternion


class PoseStampedLike(Protocol):
    """geometry_msgs/msg/PoseStamped."""

    header: _Header
    pose: _Pose


class PoseWithCovarianceStampedLike(Protocol):
    """geometry_msgs/msg/PoseWithCovarianceStamped."""

    header: _Header
    pose: _PoseWithCovariance


class TransformStampedLike(Protocol):
    """geometry_msgs/msg/TransformStamped."""

    header: _Header
    child_frame_id: str
    transform: _Transform


class PointStampedLike(Protocol):
    """geometry_msgs/msg/PointStamped."""

    header: _Header
    point: _Vector3


class OdometryLike(Protocol):
    """nav_msgs/msg/Odometry."""

    header: _Header
    child_frame_id: str
    pose: _PoseWithCovariance


class PathLike(Protocol):
    """nav_msgs/msg/Path."""

    header: _Header
    poses: Sequence[PoseStampedLike]


class TFMessageLike(Protocol):
    """tf2_msgs/msg/TFMessage."""

    transforms: Sequence[TransformStampedLike]


# --- Public results for inspection.


@dataclass(frozen=True, slots=True)
class TopicOverview:
    """One topic of a bag.

    Attributes:
        name: topic name as stored (ROS 1 topics may lack the leading slash).
        msgtype: message type, ``pkg/msg/Type``.
        message_count: messages recorded (from the bag's index or metadata).
        kind: how the type carries a pose, or None for other types.
        pose_count: poses a trajectory read from it would have before validation (the
            message count; a Path's last message's poses); 0 for non-pose topics.
        first_stamp_ns: header stamp of the first pose, or None when not read.
        last_stamp_ns: header stamp of the last pose, or None when not read.
    """

    name: str
    msgtype: str
    message_count: int
    kind: PoseKind | None
    pose_count: int = 0
    first_stamp_ns: int | None = None
    last_stamp_ns: int | None = None


@dataclass(frozen=True, slots=True, eq=False)
class BagOverview:
    """What a bag holds, read from its index plus the tf and pose messages only.

    Attributes:
        label: the bag's file name(s).
        storage_format: the container format.
        archive: ``"zip"`` when the bag was read from a zip, else ``""``.
        start_ns: receive time of the first message (0 for an empty bag).
        end_ns: receive time of the last message (0 for an empty bag).
        message_count: messages in the bag.
        topics: every topic, sorted by name.
        tf: the tf links (header stamps).
        tf_topics: the TFMessage topics read into ``tf``.
    """

    label: str
    storage_format: BagFormat
    archive: str
    start_ns: int
    end_ns: int
    message_count: int
    topics: tuple[TopicOverview, ...]
    tf: TfBuffer
    tf_topics: tuple[str, ...]


# --- Public functions.


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
    path: Path | Sequence[Path],
    selector: str,
    *,
    stamp: StampSource = StampSource.HEADER,
    name: str = "",
    max_gap_ns: int | None = None,
) -> Trajectory:
    """Read one trajectory from a bag.

    Args:
        path: a bag (see :func:`is_bag_path`), or the files of a split ROS 1 recording.
        selector: a topic (``/amcl_pose``; a ROS 1 topic may be given with or without its
            leading slash when that is unambiguous) or a tf chain ``tf:PARENT:CHILD``.
        stamp: header stamps (default) or the bag's receive times.
        name: the trajectory's name; defaults to the selector.
        max_gap_ns: for tf chains, the longest interval between two samples of a dynamic
            link that is interpolated across; None for the per-link default of
            :mod:`loceval.tftree` (max of 0.1 s and 3 median intervals).

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
    with _open_bag(path) as bag:
        if selector.startswith("tf:"):
            parent, child = _parse_tf_selector(selector)
            return _read_tf_trajectory(
                bag, selector, parent, child, stamp=stamp, name=name, max_gap_ns=max_gap_ns
            )
        return _read_topic_trajectory(bag, selector, stamp=stamp, name=name)


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
    with _open_bag(path) as bag:
        buffer = _read_tf(bag, stamp=StampSource.HEADER)
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
    with _open_bag(path) as bag:
        return _read_tf(bag, stamp=stamp)


def read_bag_overview(path: Path | Sequence[Path]) -> BagOverview:
    """Summarize a bag: format, time range, topics, tf links and pose-topic time ranges.

    Reads the bag's index and metadata, the tf messages, and only the first and last
    message of each pose topic (the last one fully for a Path); other payloads (images,
    point clouds) are never read.

    Args:
        path: a bag, or the files of a split ROS 1 recording.

    Raises:
        ReaderError: the bag cannot be read.
    """
    with _open_bag(path) as bag:
        reader = bag.reader
        buffer = _read_tf(bag, stamp=StampSource.HEADER)
        tf_topics = tuple(sorted({c.topic for c in reader.connections if _is_tf(c)}))
        pose_conns = [
            c
            for c in reader.connections
            if _normalize_msgtype(c.msgtype) in SUPPORTED_MSGTYPES and not _is_tf(c)
        ]
        firsts: dict[str, tuple[Connection, bytes]] = {}
        lasts: dict[str, tuple[Connection, bytes]] = {}
        for conn, _, raw in _raw_messages(bag, pose_conns):
            firsts.setdefault(conn.topic, (conn, raw))
            lasts[conn.topic] = (conn, raw)
        topics: list[TopicOverview] = []
        for topic, info in sorted(reader.topics.items()):
            msgtype = _normalize_msgtype(info.msgtype or "")
            kind = SUPPORTED_MSGTYPES.get(msgtype)
            entry = TopicOverview(topic, msgtype, info.msgcount, kind)
            if kind is not None and kind is not PoseKind.TF and topic in lasts:
                entry = _pose_topic_overview(bag, entry, firsts[topic], lasts[topic])
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


# --- Opening bags.


@dataclass(frozen=True, slots=True, eq=False)
class _Bag:
    reader: AnyReader
    label: str
    storage_format: BagFormat
    archive: str
    paths: tuple[Path, ...]


@contextmanager
def _open_bag(path: Path | Sequence[Path]) -> Iterator[_Bag]:
    paths = _as_paths(path)
    label = ",".join(p.name for p in paths)
    for p in paths:
        if not p.exists():
            msg = f"Bag {str(p)!r} does not exist; check the path (a ROS 2 bag is a folder)."
            raise ReaderError(msg)
    with ExitStack() as stack:
        archive = ""
        if len(paths) == 1 and paths[0].is_file() and paths[0].suffix.lower() == ".zip":
            paths = tuple(stack.enter_context(extracted_bag(paths[0])))
            archive = "zip"
        paths = tuple(_storage_path(p) for p in paths)
        if len(paths) > 1 and any(p.suffix != ".bag" for p in paths):
            names = ", ".join(p.name for p in paths)
            msg = (
                f"Only ROS 1 bags (.bag) can be read as a split set, got {names!r}; pass one "
                "ROS 2 bag directory or the .bag files of one recording."
            )
            raise ReaderError(msg)
        if paths[0].is_dir() and not (paths[0] / "metadata.yaml").is_file():
            inside = _listing(sorted(x.name for x in paths[0].iterdir())) or "nothing"
            msg = (
                f"Folder {str(paths[0])!r} has no metadata.yaml, so it is no ROS 2 bag; it "
                f"holds: {inside}; pass the bag folder or a bag file."
            )
            raise ReaderError(msg)
        if paths[0].is_file() and paths[0].suffix.lower() not in {".bag", ".mcap", ".db3"}:
            msg = (
                f"File {str(paths[0])!r} is not a bag; pass a .bag, .mcap or .db3 file, a ROS "
                "2 bag folder or a .zip of one."
            )
            raise ReaderError(msg)
        with _converted(label):
            reader = _open_reader(list(paths), stack)
        yield _Bag(reader, label, _storage_format(paths), archive, paths)


def _open_reader(paths: list[Path], stack: ExitStack) -> AnyReader:
    """Open an AnyReader; fall back to ROS 2 Humble's types for bags without definitions.

    The fallback typestore takes a tenth of a second to build, so it is only built for the
    bags that need it: old ROS 2 bags without embedded message definitions make the first
    open fail, and the second open then gets it.
    """
    reader = AnyReader(paths)
    try:
        reader.open()
    except AnyReaderError:
        reader = AnyReader(paths, default_typestore=_default_typestore())
        reader.open()
    stack.callback(reader.close)
    return reader


def _as_paths(path: Path | Sequence[Path]) -> tuple[Path, ...]:
    if isinstance(path, str | os.PathLike):
        return (Path(path),)
    paths = tuple(Path(p) for p in path)
    if not paths:
        msg = "No bag path given; pass a bag file, a ROS 2 bag folder or a zip of one."
        raise ReaderError(msg)
    return paths


def _storage_path(path: Path) -> Path:
    """Return what rosbags opens: a .db3 or metadata.yaml inside a bag opens the folder."""
    if path.name == "metadata.yaml" and path.is_file():
        return path.parent
    if path.suffix == ".db3" and (path.parent / "metadata.yaml").is_file():
        return path.parent
    return path


def _storage_format(paths: tuple[Path, ...]) -> BagFormat:
    first = paths[0]
    if first.suffix == ".bag":
        return BagFormat.ROSBAG1
    if first.suffix == ".mcap":
        return BagFormat.ROSBAG2_MCAP
    if first.is_dir() and any(".mcap" in x.suffixes for x in first.iterdir()):
        return BagFormat.ROSBAG2_MCAP
    return BagFormat.ROSBAG2_SQLITE3


@contextmanager
def _converted(label: str) -> Iterator[None]:
    """Turn rosbags' (and damaged files') exceptions into ReaderError."""
    try:
        yield
    except ReaderError:
        raise
    except FileNotFoundError as err:
        msg = f"Bag {label!r} is incomplete ({err}); copy the whole bag folder or file."
        raise ReaderError(msg) from err
    except _FOREIGN_ERRORS as err:
        detail = " ".join(str(err).split())  # parsers' reports span lines (YAML carets)
        msg = (
            f"Bag {label!r} cannot be read; it looks truncated, damaged or of an unknown "
            f"format ({type(err).__name__}: {detail}); re-copy the file, or reindex it "
            "('rosbag reindex' / 'ros2 bag reindex')."
        )
        raise ReaderError(msg) from err


def _default_typestore() -> Typestore:
    return get_typestore(Stores.ROS2_HUMBLE)


def _normalize_msgtype(msgtype: str) -> str:
    """Return ``pkg/msg/Type`` for ``pkg/Type`` (ROS 1) and ``pkg/msg/Type``."""
    parts = msgtype.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return msgtype


def _is_tf(conn: Connection) -> bool:
    return _normalize_msgtype(conn.msgtype) == TF_MSGTYPE


def _is_static_topic(topic: str) -> bool:
    return topic.rstrip("/").rsplit("/", 1)[-1] == "tf_static"


# --- Reading messages.


def _raw_messages(
    bag: _Bag, connections: Sequence[Connection]
) -> Iterator[tuple[Connection, int, bytes]]:
    """Yield ``(connection, receive_ns, rawdata)`` of the connections.

    ROS 2 bags yield in receive order. ROS 1 bags yield topic by topic, each in receive
    order: rosbags reloads a chunk whenever consecutive messages lie in different chunks,
    and merging topics recorded into separate chunks (as in bags written topic by topic)
    made that thirty times slower.

    Checks that as many messages came out as the bag's index recorded: damaged chunks can
    otherwise vanish silently.
    """
    if not connections:
        return
    counts: dict[str, int] = dict.fromkeys((c.topic for c in connections), 0)
    if bag.reader.is2:
        groups = [list(connections)]
    else:
        groups = [[c for c in connections if c.topic == topic] for topic in counts]
    for group in groups:
        indexed = _indexed_mcap_messages(bag, group)
        with _converted(bag.label):
            source = indexed if indexed is not None else bag.reader.messages(group)
            for conn, receive_ns, raw in source:
                counts[conn.topic] += 1
                yield conn, receive_ns, raw
    for topic, seen in counts.items():
        recorded = sum(c.msgcount for c in connections if c.topic == topic)
        if seen < recorded:
            msg = (
                f"Bag {bag.label!r} looks damaged: topic {topic!r} gave {seen} of the "
                f"{recorded} messages its index records; re-copy the file or reindex it."
            )
            raise ReaderError(msg)


def _indexed_mcap_messages(
    bag: _Bag, connections: Sequence[Connection]
) -> list[tuple[Connection, int, bytes]] | None:
    """Read MCAP messages through the file's index, or return None when it cannot serve."""
    if bag.storage_format is not BagFormat.ROSBAG2_MCAP:
        return None
    files: list[Path] = []
    for reader in bag.reader.readers:
        if not isinstance(reader, Rosbag2Reader) or reader.compression_mode:
            return None
        rpath = Path(str(reader.path))
        files.extend(sorted(rpath.glob("*.mcap")) if rpath.is_dir() else [rpath])
    keys = [(c.topic, c.msgtype) for c in connections]
    out: list[tuple[Connection, int, bytes]] = []
    for file in files:
        messages = read_indexed_messages(file, keys)
        if messages is None:
            return None
        out.extend((connections[i], log_time, data) for log_time, i, data in messages)
    if len(files) > 1:
        out.sort(key=lambda x: x[1])
    return out


def _deserialize(bag: _Bag, raw: bytes, msgtype: str) -> object:
    with _converted(bag.label):
        return bag.reader.deserialize(raw, msgtype)


# --- Topics.


def _match_topic(bag: _Bag, topic: str) -> str:
    topics = bag.reader.topics
    if topic in topics:
        return topic
    matches = [t for t in topics if t.lstrip("/") == topic.lstrip("/")]
    if len(matches) == 1:
        return matches[0]
    listing = _listing([f"{t} ({info.msgtype})" for t, info in sorted(topics.items())])
    msg = (
        f"Topic {topic!r} is not in bag {bag.label!r}; topics in the bag: {listing or 'none'}; "
        "type one of them, or tf:PARENT:CHILD for a tf chain."
    )
    raise ReaderError(msg)


def _read_topic_trajectory(
    bag: _Bag, selector: str, *, stamp: StampSource, name: str
) -> Trajectory:
    topic = _match_topic(bag, selector)
    conns = [c for c in bag.reader.connections if c.topic == topic]
    msgtypes = sorted({_normalize_msgtype(c.msgtype) for c in conns})
    where = f"{bag.label}@{selector}"
    unsupported = [m for m in msgtypes if m not in SUPPORTED_MSGTYPES]
    if unsupported:
        supported = ", ".join(k for k in SUPPORTED_MSGTYPES if k != TF_MSGTYPE)
        msg = (
            f"Topic {topic!r} in bag {bag.label!r} has type {unsupported[0]!r}, which holds "
            f"no pose; supported types: {supported}; pick a topic of one of them or a tf "
            "chain (run 'loceval inspect' to list them)."
        )
        raise ReaderError(msg)
    if len(msgtypes) > 1:
        msg = (
            f"Topic {topic!r} in bag {bag.label!r} mixes the types {', '.join(msgtypes)}; "
            "record one type per topic."
        )
        raise ReaderError(msg)
    kind = SUPPORTED_MSGTYPES[msgtypes[0]]
    if kind is PoseKind.TF:
        buffer = _read_tf(bag, stamp=stamp)
        msg = (
            f"Topic {topic!r} holds tf messages, which form a tree, not one trajectory; "
            f"select a chain as tf:PARENT:CHILD (frames: {buffer.describe_frames() or 'none'})."
        )
        raise ReaderError(msg)
    if kind is PoseKind.PATH:
        return _read_path(bag, conns, where=where, selector=selector, stamp=stamp, name=name)
    stamps: list[int] = []
    values: list[float] = []
    frame_ids: set[str] = set()
    child_ids: set[str] = set()
    with_orientation = kind is not PoseKind.POINT
    for conn, receive_ns, raw in _raw_messages(bag, conns):
        msg_obj = _deserialize(bag, raw, conn.msgtype)
        header, child, position, orientation = _pose_fields(kind, msg_obj)
        stamps.append(
            receive_ns
            if stamp is StampSource.RECEIVE
            else header.stamp.sec * _NS + header.stamp.nanosec
        )
        frame_ids.add(header.frame_id)
        child_ids.add(child)
        if orientation is None:
            values.extend((position.x, position.y, position.z))
        else:
            values.extend(
                (
                    position.x,
                    position.y,
                    position.z,
                    orientation.x,
                    orientation.y,
                    orientation.z,
                    orientation.w,
                )
            )
    width = 7 if with_orientation else 3
    array = np.array(values, dtype=np.float64).reshape(-1, width)
    return _finish(
        np.array(stamps, dtype=np.int64),
        array[:, :3],
        array[:, 3:] if with_orientation else None,
        where=where,
        name=name or selector,
        frame_ids=frame_ids,
        child_ids=child_ids,
    )


def _pose_fields(kind: PoseKind, msg: object) -> tuple[_Header, str, _Vector3, _Quaternion | None]:
    """Return header, child frame id, position and orientation (None for points)."""
    if kind is PoseKind.POSE:
        pose_msg = cast("PoseStampedLike", msg)
        pose = pose_msg.pose
        return pose_msg.header, "", pose.position, pose.orientation
    if kind is PoseKind.POSE_WITH_COVARIANCE:
        cov_msg = cast("PoseWithCovarianceStampedLike", msg)
        pose = cov_msg.pose.pose
        return cov_msg.header, "", pose.position, pose.orientation
    if kind is PoseKind.ODOMETRY:
        odom = cast("OdometryLike", msg)
        pose = odom.pose.pose
        return odom.header, odom.child_frame_id, pose.position, pose.orientation
    if kind is PoseKind.TRANSFORM:
        tr = cast("TransformStampedLike", msg)
        return tr.header, tr.child_frame_id, tr.transform.translation, tr.transform.rotation
    point = cast("PointStampedLike", msg)
    return point.header, "", point.point, None


def _read_path(
    bag: _Bag,
    conns: Sequence[Connection],
    *,
    where: str,
    selector: str,
    stamp: StampSource,
    name: str,
) -> Trajectory:
    if stamp is StampSource.RECEIVE:
        msg = (
            f"Topic {selector!r} is a nav_msgs/Path, whose poses have no receive times of "
            "their own; read it with header stamps."
        )
        raise ReaderError(msg)
    last: tuple[Connection, bytes] | None = None
    for conn, _, raw in _raw_messages(bag, conns):
        last = (conn, raw)
    if last is None:
        msg = f"Topic {selector!r} in bag {bag.label!r} has no messages; pick another topic."
        raise ReaderError(msg)
    path_msg = cast("PathLike", _deserialize(bag, last[1], last[0].msgtype))
    stamps: list[int] = []
    values: list[float] = []
    for item in path_msg.poses:
        header, pose = item.header, item.pose
        p, q = pose.position, pose.orientation
        stamps.append(header.stamp.sec * _NS + header.stamp.nanosec)
        values.extend((p.x, p.y, p.z, q.x, q.y, q.z, q.w))
    array = np.array(values, dtype=np.float64).reshape(-1, 7)
    return _finish(
        np.array(stamps, dtype=np.int64),
        array[:, :3],
        array[:, 3:],
        where=where,
        name=name or selector,
        frame_ids={path_msg.header.frame_id},
        child_ids={""},
        warnings=(f"{where}: nav_msgs/Path; the poses of its last message are used.",),
    )


def _finish(
    stamps: StampsNs,
    positions: FloatArray,
    quats: FloatArray | None,
    *,
    where: str,
    name: str,
    frame_ids: set[str],
    child_ids: set[str],
    warnings: tuple[str, ...] = (),
) -> Trajectory:
    notes = list(warnings)
    if stamps.size >= MIN_POSES and np.unique(stamps).size < MIN_POSES:
        msg = (
            f"{where}: {stamps.size} messages but only {np.unique(stamps).size} distinct "
            "header stamps (the publisher does not fill header.stamp); evaluate with "
            "--stamp receive to use the bag's receive times."
        )
        raise ReaderError(msg)
    frame_id = min(frame_ids) if frame_ids else ""
    if len(frame_ids) > 1:
        notes.append(f"{where}: poses in several frames ({', '.join(sorted(frame_ids))}).")
    child_id = min(child_ids) if child_ids else ""
    return build_trajectory(
        stamps,
        positions,
        quats,
        where=where,
        name=name,
        source=where,
        frame_id=frame_id.lstrip("/"),
        child_frame_id=child_id.lstrip("/"),
        warnings=tuple(notes),
    )


def _pose_topic_overview(
    bag: _Bag,
    entry: TopicOverview,
    first: tuple[Connection, bytes],
    last: tuple[Connection, bytes],
) -> TopicOverview:
    kind = entry.kind
    if kind is None:
        return entry
    if kind is PoseKind.PATH:
        path_msg = cast("PathLike", _deserialize(bag, last[1], last[0].msgtype))
        stamps = [p.header.stamp.sec * _NS + p.header.stamp.nanosec for p in path_msg.poses]
        return TopicOverview(
            entry.name,
            entry.msgtype,
            entry.message_count,
            kind,
            len(stamps),
            min(stamps) if stamps else None,
            max(stamps) if stamps else None,
        )
    ends = []
    for conn, raw in (first, last):
        header = _pose_fields(kind, _deserialize(bag, raw, conn.msgtype))[0]
        ends.append(header.stamp.sec * _NS + header.stamp.nanosec)
    return TopicOverview(
        entry.name, entry.msgtype, entry.message_count, kind, entry.message_count, *ends
    )


# --- tf.


def _parse_tf_selector(selector: str) -> tuple[str, str]:
    parts = selector.split(":")
    if len(parts) != 3 or not parts[1].strip("/") or not parts[2].strip("/"):
        msg = (
            f"tf selector {selector!r} is malformed; type tf:PARENT:CHILD, for example "
            "tf:map:base_link."
        )
        raise ReaderError(msg)
    return parts[1].strip().lstrip("/"), parts[2].strip().lstrip("/")


def _read_tf_trajectory(
    bag: _Bag,
    selector: str,
    parent: str,
    child: str,
    *,
    stamp: StampSource,
    name: str,
    max_gap_ns: int | None,
) -> Trajectory:
    where = f"{bag.label}@{selector}"
    buffer = _read_tf(bag, stamp=stamp)
    if not buffer.links:
        topics = _listing(sorted(bag.reader.topics))
        msg = (
            f"Bag {bag.label!r} holds no tf messages (topics: {topics or 'none'}); select a "
            "pose topic instead of a tf chain."
        )
        raise ReaderError(msg)
    steps = _find_chain(buffer, parent, child)
    chain = compose_chain(buffer, parent, child, max_gap_ns=max_gap_ns)
    total = chain.stamps_ns.shape[0] + chain.dropped
    if chain.stamps_ns.shape[0] < MIN_POSES:
        ranges = "; ".join(
            f"{s.link.name} {s.link.stamps_ns[0] / _NS:.3f}..{s.link.stamps_ns[-1] / _NS:.3f} s"
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


def _read_tf(bag: _Bag, *, stamp: StampSource) -> TfBuffer:
    conns = [c for c in bag.reader.connections if _is_tf(c)]
    collector = _TfCollector(
        receive=stamp is StampSource.RECEIVE,
        cdr=bag.reader.is2 and _standard_tf_layout(bag.reader.typestore),
    )
    with _damaged_tf(bag.label):
        for conn, receive_ns, raw in _raw_messages(bag, conns):
            static = _is_static_topic(conn.topic)
            if not collector.add_raw(raw, receive_ns, static=static):
                tf_msg = cast("TFMessageLike", _deserialize(bag, raw, conn.msgtype))
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
            link.stamps.append(receive_ns if self._receive else st.sec * _NS + st.nanosec)
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
            link.stamps.append(receive_ns if self._receive else sec * _NS + nanosec)
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
                stamps = sec.astype(np.int64) * _NS + nanosec.astype(np.int64)
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


def _listing(items: Sequence[str]) -> str:
    if len(items) <= _MAX_LISTED:
        return ", ".join(items)
    return f"{', '.join(items[:_MAX_LISTED])} and {len(items) - _MAX_LISTED} more"
