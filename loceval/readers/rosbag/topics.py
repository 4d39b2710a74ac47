"""Trajectories from pose topics (PoseStamped, Odometry, Path, ...), and their overview."""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np
from rosbags.interfaces import Connection

from loceval.core.arrays import FloatArray, StampsNs
from loceval.errors import ReaderError
from loceval.readers._common import build_trajectory
from loceval.readers.rosbag.bagfile import (
    Bag,
    deserialize,
    listing,
    normalize_msgtype,
    raw_messages,
)
from loceval.readers.rosbag.messages import (
    NS,
    SUPPORTED_MSGTYPES,
    TF_MSGTYPE,
    HeaderLike,
    OdometryLike,
    PathLike,
    PointStampedLike,
    PoseKind,
    PoseStampedLike,
    PoseWithCovarianceStampedLike,
    QuaternionLike,
    StampSource,
    TopicOverview,
    TransformStampedLike,
    Vector3Like,
)
from loceval.readers.rosbag.tf import read_tf
from loceval.trajectory import MIN_POSES, Trajectory

__all__ = ["match_topic", "pose_topic_overview", "read_topic_trajectory"]


def match_topic(bag: Bag, topic: str) -> str:
    """Return the bag's topic named ``topic`` (a leading ``/`` may differ).

    Raises:
        ReaderError: no topic, or more than one, matches; the message lists the bag's topics.
    """
    topics = bag.reader.topics
    if topic in topics:
        return topic
    matches = [t for t in topics if t.lstrip("/") == topic.lstrip("/")]
    if len(matches) == 1:
        return matches[0]
    known = listing([f"{t} ({info.msgtype})" for t, info in sorted(topics.items())])
    msg = (
        f"Topic {topic!r} is not in bag {bag.label!r}; topics in the bag: {known or 'none'}; "
        "type one of them, or tf:PARENT:CHILD for a tf chain."
    )
    raise ReaderError(msg)


def read_topic_trajectory(bag: Bag, selector: str, *, stamp: StampSource, name: str) -> Trajectory:
    """Read the trajectory of one pose topic."""
    topic = match_topic(bag, selector)
    conns = [c for c in bag.reader.connections if c.topic == topic]
    msgtypes = sorted({normalize_msgtype(c.msgtype) for c in conns})
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
        buffer = read_tf(bag, stamp=stamp)
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
    covariances: list[Sequence[float]] | None = (
        [] if kind in {PoseKind.POSE_WITH_COVARIANCE, PoseKind.ODOMETRY} else None
    )
    for conn, receive_ns, raw in raw_messages(bag, conns):
        msg_obj = deserialize(bag, raw, conn.msgtype)
        header, child, position, orientation = _pose_fields(kind, msg_obj)
        if covariances is not None:
            covariances.append(
                cast("PoseWithCovarianceStampedLike | OdometryLike", msg_obj).pose.covariance
            )
        stamps.append(
            receive_ns
            if stamp is StampSource.RECEIVE
            else header.stamp.sec * NS + header.stamp.nanosec
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
    cov6, cov_notes = _covariances(covariances, where=where)
    return _finish(
        np.array(stamps, dtype=np.int64),
        array[:, :3],
        array[:, 3:] if with_orientation else None,
        where=where,
        name=name or selector,
        frame_ids=frame_ids,
        child_ids=child_ids,
        warnings=cov_notes,
        cov6=cov6,
    )


def _covariances(
    covariances: list[Sequence[float]] | None, *, where: str
) -> tuple[FloatArray | None, tuple[str, ...]]:
    """Return the (N, 6, 6) pose covariances of the messages, or None when none is reported.

    A message reports no covariance when all 36 values are zero or the first is -1 (the ROS
    convention for "unknown"); then, or when a covariance is not finite and symmetric, the
    trajectory carries none (the evaluation's consistency check is skipped).
    """
    if not covariances:
        return None, ()
    cov = np.asarray(covariances, dtype=np.float64).reshape(-1, 6, 6)
    if not cov.any() or (cov[:, 0, 0] == -1.0).any():
        return None, ()
    finite = bool(np.isfinite(cov).all())
    scale = max(float(np.abs(cov[np.isfinite(cov)]).max(initial=0.0)), 1.0)
    if not finite or not np.allclose(cov, cov.transpose(0, 2, 1), rtol=0.0, atol=1e-9 * scale):
        note = (
            f"{where}: the pose covariances are not finite and symmetric, so they are not "
            "used (no consistency check)."
        )
        return None, (note,)
    return cov, ()


def _pose_fields(
    kind: PoseKind, msg: object
) -> tuple[HeaderLike, str, Vector3Like, QuaternionLike | None]:
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
    bag: Bag,
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
    for conn, _, raw in raw_messages(bag, conns):
        last = (conn, raw)
    if last is None:
        msg = f"Topic {selector!r} in bag {bag.label!r} has no messages; pick another topic."
        raise ReaderError(msg)
    path_msg = cast("PathLike", deserialize(bag, last[1], last[0].msgtype))
    stamps: list[int] = []
    values: list[float] = []
    for item in path_msg.poses:
        header, pose = item.header, item.pose
        p, q = pose.position, pose.orientation
        stamps.append(header.stamp.sec * NS + header.stamp.nanosec)
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
    cov6: FloatArray | None = None,
) -> Trajectory:
    notes = list(warnings)
    if stamps.size >= MIN_POSES and np.unique(stamps).size < MIN_POSES:
        msg = (
            f"{where}: {stamps.size} messages but only {np.unique(stamps).size} distinct "
            "header stamps (the publisher does not fill header.stamp); read the bag's "
            "receive times instead."
        )
        raise ReaderError(msg, option="stamp", suggest="receive")
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
        cov6=cov6,
    )


def pose_topic_overview(
    bag: Bag,
    entry: TopicOverview,
    first: tuple[Connection, bytes],
    last: tuple[Connection, bytes],
) -> TopicOverview:
    """Fill a pose topic's pose count and time range from its first and last message."""
    kind = entry.kind
    if kind is None:
        return entry
    if kind is PoseKind.PATH:
        path_msg = cast("PathLike", deserialize(bag, last[1], last[0].msgtype))
        stamps = [p.header.stamp.sec * NS + p.header.stamp.nanosec for p in path_msg.poses]
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
        header = _pose_fields(kind, deserialize(bag, raw, conn.msgtype))[0]
        ends.append(header.stamp.sec * NS + header.stamp.nanosec)
    return TopicOverview(
        entry.name, entry.msgtype, entry.message_count, kind, entry.message_count, *ends
    )
