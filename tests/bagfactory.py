"""Write small bags of every container and pose message type, as rosbags' own tests do.

Messages are described container-neutrally and built with the typestore of the target
format (ROS 2 Humble for rosbag2 CDR, ROS 1 Noetic for rosbag1), so the same records can
be written to a ROS 1 bag, a ROS 2 sqlite3 bag and a ROS 2 MCAP bag and read back alike.
"""

from __future__ import annotations

import functools
import zipfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

NS = 1_000_000_000
T0_NS = 1_700_000_000 * NS

POSE = "geometry_msgs/msg/PoseStamped"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
TRANSFORM = "geometry_msgs/msg/TransformStamped"
POINT = "geometry_msgs/msg/PointStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
PATH = "nav_msgs/msg/Path"
TF = "tf2_msgs/msg/TFMessage"
IMAGE = "sensor_msgs/msg/Image"
IMU = "sensor_msgs/msg/Imu"
RANGE = "sensor_msgs/msg/Range"
STRING = "std_msgs/msg/String"

FORMATS = ("rosbag1", "sqlite3", "mcap")


@functools.cache
def typestore(fmt: str) -> Typestore:
    """Return the typestore that serializes messages for ``fmt``."""
    if fmt != "rosbag1":
        return get_typestore(Stores.ROS2_HUMBLE)
    store = get_typestore(Stores.ROS1_NOETIC)
    # Noetic's store lacks tf2_msgs; its ROS 1 definition is one line.
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
    return store


@dataclass(frozen=True)
class Poses:
    """Stamped poses for one message stream."""

    stamps_ns: np.ndarray
    positions: np.ndarray
    quats: np.ndarray


@dataclass(frozen=True)
class Tf:
    """One transform of a TFMessage."""

    stamp_ns: int
    parent: str
    child: str
    xyz: Sequence[float]
    quat: Sequence[float]


@dataclass(frozen=True)
class Record:
    """One message to write: topic, type, receive time and a container-neutral payload."""

    topic: str
    msgtype: str
    receive_ns: int
    payload: object
    frame_id: str = "map"
    child_frame_id: str = "base_link"
    extra: dict[str, object] = field(default_factory=dict)


def random_poses(rng: np.random.Generator, n: int, *, start_ns: int = T0_NS, dt_ns: int) -> Poses:
    """Return ``n`` random poses at a fixed interval (jittered by < 1 ms)."""
    jitter = rng.integers(0, 1_000_000, size=n)
    stamps = start_ns + np.arange(n, dtype=np.int64) * dt_ns + jitter
    positions = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1)[:, None]
    return Poses(stamps, positions, quats)


def pose_records(
    topic: str,
    msgtype: str,
    poses: Poses,
    *,
    frame_id: str = "map",
    child_frame_id: str = "base_link",
    receive_delay_ns: int = 5_000_000,
) -> list[Record]:
    """Return one record per pose for a stamped pose type (not Path or TFMessage)."""
    return [
        Record(
            topic,
            msgtype,
            int(poses.stamps_ns[i]) + receive_delay_ns,
            (int(poses.stamps_ns[i]), poses.positions[i], poses.quats[i]),
            frame_id,
            child_frame_id,
        )
        for i in range(len(poses.stamps_ns))
    ]


def path_records(topic: str, poses: Poses, *, cuts: Sequence[int]) -> list[Record]:
    """Return nav_msgs/Path records holding the first ``cut`` poses each (a growing path)."""
    return [
        Record(topic, PATH, int(poses.stamps_ns[cut - 1]) + 1_000_000, (poses, cut)) for cut in cuts
    ]


def tf_records(
    transforms: Iterable[Tf], *, topic: str = "/tf", receive_delay_ns: int = 2_000_000
) -> list[Record]:
    """Return one TFMessage record per transform."""
    return [Record(topic, TF, t.stamp_ns + receive_delay_ns, [t]) for t in transforms]


def link_transforms(parent: str, child: str, poses: Poses) -> list[Tf]:
    """Return the transforms of one tf link over time."""
    return [
        Tf(int(poses.stamps_ns[i]), parent, child, poses.positions[i], poses.quats[i])
        for i in range(len(poses.stamps_ns))
    ]


def image_record(topic: str, receive_ns: int, *, size: int = 64) -> Record:
    """Return a small rgb8 image record (never a pose source)."""
    return Record(topic, IMAGE, receive_ns, size, frame_id="camera")


def build_message(fmt: str, record: Record) -> object:  # noqa: C901, PLR0911
    """Build the typestore message object of ``record`` for ``fmt``."""
    types = typestore(fmt).types

    def header(stamp_ns: int, frame_id: str) -> object:
        sec, nanosec = divmod(stamp_ns, NS)
        stamp = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
        if fmt == "rosbag1":
            return types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
        return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def point(xyz: Sequence[float]) -> object:
        return types["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))

    def vector(xyz: Sequence[float]) -> object:
        return types["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))

    def quaternion(q: Sequence[float]) -> object:
        return types["geometry_msgs/msg/Quaternion"](
            x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
        )

    def pose(xyz: Sequence[float], q: Sequence[float]) -> object:
        return types["geometry_msgs/msg/Pose"](position=point(xyz), orientation=quaternion(q))

    def with_cov(xyz: Sequence[float], q: Sequence[float]) -> object:
        cov = record.extra.get("covariance")
        values = np.zeros(36) if cov is None else np.asarray(cov, dtype=np.float64).ravel()
        return types["geometry_msgs/msg/PoseWithCovariance"](pose=pose(xyz, q), covariance=values)

    def transform_stamped(t: Tf) -> object:
        return types["geometry_msgs/msg/TransformStamped"](
            header=header(t.stamp_ns, t.parent),
            child_frame_id=t.child,
            transform=types["geometry_msgs/msg/Transform"](
                translation=vector(t.xyz), rotation=quaternion(t.quat)
            ),
        )

    kind = record.msgtype
    if kind == STRING:
        return types[STRING](data=str(record.payload))
    if kind == TF:
        assert isinstance(record.payload, list)
        return types[TF](transforms=[transform_stamped(t) for t in record.payload])
    if kind == IMAGE:
        assert isinstance(record.payload, int)
        size = record.payload
        return types[IMAGE](
            header=header(record.receive_ns, record.frame_id),
            height=size,
            width=size,
            encoding="rgb8",
            is_bigendian=0,
            step=3 * size,
            data=np.zeros(3 * size * size, dtype=np.uint8),
        )
    if kind == PATH:
        poses, cut = record.payload  # type: ignore[misc]
        items = [
            types[POSE](
                header=header(int(poses.stamps_ns[i]), record.frame_id),
                pose=pose(poses.positions[i], poses.quats[i]),
            )
            for i in range(cut)
        ]
        return types[PATH](header=header(record.receive_ns, record.frame_id), poses=items)
    if kind == RANGE:  # payload (header stamp, range); frame_id names the anchor
        range_stamp_ns, value = record.payload  # type: ignore[misc]
        return types[RANGE](
            header=header(range_stamp_ns, record.frame_id),
            radiation_type=2,
            field_of_view=0.0,
            min_range=0.0,
            max_range=100.0,
            range=float(value),
        )
    stamp_ns, xyz, q = record.payload  # type: ignore[misc]
    hdr = header(stamp_ns, record.frame_id)
    if kind == POSE:
        return types[POSE](header=hdr, pose=pose(xyz, q))
    if kind == POSE_COV:
        return types[POSE_COV](header=hdr, pose=with_cov(xyz, q))
    if kind == TRANSFORM:
        return transform_stamped(Tf(stamp_ns, record.frame_id, record.child_frame_id, xyz, q))
    if kind == POINT:
        return types[POINT](header=hdr, point=point(xyz))
    if kind == ODOMETRY:
        twist = types["geometry_msgs/msg/TwistWithCovariance"](
            twist=types["geometry_msgs/msg/Twist"](
                linear=vector((0, 0, 0)), angular=vector((0, 0, 0))
            ),
            covariance=np.zeros(36),
        )
        return types[ODOMETRY](
            header=hdr,
            child_frame_id=record.child_frame_id,
            pose=with_cov(xyz, q),
            twist=twist,
        )
    if kind == IMU:
        return types[IMU](
            header=hdr,
            orientation=quaternion(q),
            orientation_covariance=np.zeros(9),
            angular_velocity=vector((0, 0, 0)),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vector((0, 0, 0)),
            linear_acceleration_covariance=np.zeros(9),
        )
    msg = f"bagfactory cannot build {kind!r}"
    raise ValueError(msg)


def write_bag(
    path: Path,
    records: Iterable[Record],
    *,
    fmt: str,
    compression: str | None = None,
    little_endian: bool = True,
) -> Path:
    """Write ``records`` (sorted by receive time here) and return the path to read.

    Args:
        path: for rosbag1 a ``.bag`` file, for rosbag2 the bag directory.
        records: the messages.
        fmt: ``rosbag1``, ``sqlite3`` or ``mcap``.
        compression: rosbag1 ``bz2``/``lz4``; rosbag2 ``message``/``file`` (zstd), or
            ``storage`` (MCAP zstd chunks).
        little_endian: rosbag2 CDR byte order.
    """
    ordered = sorted(records, key=lambda r: r.receive_ns)
    store = typestore(fmt)
    if fmt == "rosbag1":
        writer1 = Writer1(path)
        if compression:
            writer1.set_compression(Writer1.CompressionFormat[compression.upper()])
        with writer1:
            conns1: dict[tuple[str, str], object] = {}
            for record in ordered:
                key = (record.topic, record.msgtype)
                if key not in conns1:
                    conns1[key] = writer1.add_connection(
                        record.topic, record.msgtype, typestore=store
                    )
                data = store.serialize_ros1(build_message(fmt, record), record.msgtype)
                writer1.write(conns1[key], record.receive_ns, data)  # type: ignore[arg-type]
        return path
    plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
    writer2 = Writer2(path, version=9, storage_plugin=plugin)
    if compression:
        writer2.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
    with writer2:
        conns2: dict[tuple[str, str], object] = {}
        for record in ordered:
            key = (record.topic, record.msgtype)
            if key not in conns2:
                conns2[key] = writer2.add_connection(record.topic, record.msgtype, typestore=store)
            data = store.serialize_cdr(
                build_message(fmt, record), record.msgtype, little_endian=little_endian
            )
            writer2.write(conns2[key], record.receive_ns, data)  # type: ignore[arg-type]
    return path


def bag_path(tmp_path: Path, fmt: str, name: str = "rec") -> Path:
    """Return where to write a bag of ``fmt`` under ``tmp_path``."""
    return tmp_path / (f"{name}.bag" if fmt == "rosbag1" else name)


def zip_directory(directory: Path, zip_path: Path, *, prefix: str = "") -> Path:
    """Zip every file under ``directory`` (names relative to its parent, plus ``prefix``)."""
    with zipfile.ZipFile(zip_path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(directory.rglob("*")):
            if file.is_file():
                archive.write(file, prefix + str(file.relative_to(directory.parent)))
    return zip_path


def zip_file(file: Path, zip_path: Path) -> Path:
    """Zip one file under its own name."""
    with zipfile.ZipFile(zip_path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.write(file, file.name)
    return zip_path
