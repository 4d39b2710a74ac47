"""Message types a bag's poses come in, and the overview of a bag (no rosbags import).

:data:`SUPPORTED_MSGTYPES` maps the message types that hold poses to how they carry them;
the ``...Like`` protocols describe the fields of the messages rosbags deserializes;
:class:`BagOverview` is what :func:`loceval.readers.rosbag.read_bag_overview` returns.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from types import MappingProxyType
from typing import Final, Protocol

from loceval.optionspec import StampSource
from loceval.readers.tftree import TfBuffer

__all__ = [
    "NS",
    "SUPPORTED_MSGTYPES",
    "TF_MSGTYPE",
    "BagFormat",
    "BagOverview",
    "HeaderLike",
    "OdometryLike",
    "PathLike",
    "PointStampedLike",
    "PoseKind",
    "PoseStampedLike",
    "PoseWithCovarianceStampedLike",
    "QuaternionLike",
    "StampSource",
    "TFMessageLike",
    "TopicOverview",
    "TransformStampedLike",
    "Vector3Like",
]

NS: Final = 1_000_000_000
"""Nanoseconds per second."""


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


# --- Shapes of the deserialized messages (rosbags builds dataclasses with these fields).


class _Time(Protocol):
    sec: int
    nanosec: int


class HeaderLike(Protocol):
    """std_msgs/msg/Header."""

    stamp: _Time
    frame_id: str


class Vector3Like(Protocol):
    """geometry_msgs/msg/Vector3 or Point."""

    x: float
    y: float
    z: float


class QuaternionLike(Protocol):
    """geometry_msgs/msg/Quaternion."""

    x: float
    y: float
    z: float
    w: float


class _Pose(Protocol):
    position: Vector3Like
    orientation: QuaternionLike


class _PoseWithCovariance(Protocol):
    pose: _Pose
    covariance: Sequence[float]
    """36 floats, row-major 6x6, ``x y z rx ry rz`` in the header's frame."""


class _Transform(Protocol):
    translation: Vector3Like
    rotation: QuaternionLike


class PoseStampedLike(Protocol):
    """geometry_msgs/msg/PoseStamped."""

    header: HeaderLike
    pose: _Pose


class PoseWithCovarianceStampedLike(Protocol):
    """geometry_msgs/msg/PoseWithCovarianceStamped."""

    header: HeaderLike
    pose: _PoseWithCovariance


class TransformStampedLike(Protocol):
    """geometry_msgs/msg/TransformStamped."""

    header: HeaderLike
    child_frame_id: str
    transform: _Transform


class PointStampedLike(Protocol):
    """geometry_msgs/msg/PointStamped."""

    header: HeaderLike
    point: Vector3Like


class OdometryLike(Protocol):
    """nav_msgs/msg/Odometry."""

    header: HeaderLike
    child_frame_id: str
    pose: _PoseWithCovariance


class PathLike(Protocol):
    """nav_msgs/msg/Path."""

    header: HeaderLike
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
