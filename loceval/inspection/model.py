"""The description of an input: one typed result for every input kind, JSON-ready.

:class:`Inspection` is what :func:`loceval.inspection.inspect` returns for a trajectory file,
a Motive take, a bag or a URDF file. Fields that do not apply to a kind keep their empty
defaults and :meth:`Inspection.to_dict` leaves their keys out, so each kind's JSON holds
the keys that describe it:

- every kind: ``path``, ``kind``, ``format``, ``sources``, ``warnings``;
- bags: ``storage_format``, ``archive``, ``start_ns``, ``end_ns``, ``duration_s``,
  ``message_count``, ``topics``, ``tf_tree``;
- files that hold one trajectory: ``source``, ``poses``, ``start_s``, ``end_s``,
  ``duration_s``, ``length_m``, ``rate_hz``, ``orientation`` (a summary of that trajectory);
- URDF files: ``robot``, ``links``, ``joints``;
- control-point surveys: ``points``, ``ids``, ``extent_m`` (no sources: not a trajectory);
- visits tables: ``visits``, ``ids``, ``start_s``, ``end_s``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

__all__ = [
    "FrameInspection",
    "Inspection",
    "JointInspection",
    "SourceInspection",
    "TopicInspection",
]

NS: Final = 1_000_000_000
"""Nanoseconds per second."""


@dataclass(frozen=True, slots=True)
class TopicInspection:
    """One topic of a bag.

    Attributes:
        name: topic name.
        msgtype: message type (``pkg/msg/Type``).
        message_count: messages recorded.
        pose_source: whether a trajectory can be read from it by name (tf topics are read
            as chains instead).
    """

    name: str
    msgtype: str
    message_count: int
    pose_source: bool

    def to_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict."""
        return {
            "name": self.name,
            "msgtype": self.msgtype,
            "message_count": self.message_count,
            "pose_source": self.pose_source,
        }


@dataclass(frozen=True, slots=True)
class FrameInspection:
    """One frame of a bag's tf tree, in depth-first order.

    Attributes:
        frame: frame id.
        parent: parent frame id, or ``""`` for a root.
        depth: 0 for a root, 1 for its children, ...
        static: the link to the parent is on ``/tf_static``.
        rate_hz: median rate of the link to the parent (0 for static links and roots).
        message_count: transforms received for the link to the parent.
        first_stamp_ns: first header stamp of the link (None for roots).
        last_stamp_ns: last header stamp of the link (None for roots).
    """

    frame: str
    parent: str
    depth: int
    static: bool
    rate_hz: float
    message_count: int
    first_stamp_ns: int | None
    last_stamp_ns: int | None

    def to_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict."""
        return {
            "frame": self.frame,
            "parent": self.parent or None,
            "depth": self.depth,
            "static": self.static,
            "rate_hz": round(self.rate_hz, 3),
            "message_count": self.message_count,
            "first_stamp_ns": self.first_stamp_ns,
            "last_stamp_ns": self.last_stamp_ns,
        }


@dataclass(frozen=True, slots=True)
class SourceInspection:
    """A trajectory that can be read from the input.

    Attributes:
        selector: what to type after ``FILE@`` (a topic, ``tf:PARENT:CHILD`` or a rigid
            body), or None for a file that holds one trajectory (type ``FILE``).
        kind: ``topic``, ``tf``, ``rigid_body`` or ``file``.
        description: the message type, the tf chain (``map -> odom -> base_link``), or
            what the file is (``TUM trajectory``).
        pose_count: poses (for tf chains after dropping uncovered stamps; for topics the
            message count, or a Path's last message's poses).
        first_stamp_ns: first pose's stamp, or None when unknown.
        last_stamp_ns: last pose's stamp, or None when unknown.
        rate_hz: pose rate: the median for read trajectories and tf chains, the mean from
            the first and last stamp for bag topics (0 when it cannot be told).
        length_m: path length in metres, or None when the poses were not read (bags).
        orientation: whether the poses carry orientations, or None when unknown.
        indexed: the stamps are pose numbers, not times (KITTI without its times file).
    """

    selector: str | None
    kind: str
    description: str
    pose_count: int
    first_stamp_ns: int | None
    last_stamp_ns: int | None
    rate_hz: float = 0.0
    length_m: float | None = None
    orientation: bool | None = None
    indexed: bool = False

    @property
    def duration_s(self) -> float:
        """Time from the first to the last pose in seconds (0 when unknown)."""
        if self.first_stamp_ns is None or self.last_stamp_ns is None:
            return 0.0
        return (self.last_stamp_ns - self.first_stamp_ns) / NS

    def to_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict."""
        return {
            "selector": self.selector,
            "kind": self.kind,
            "description": self.description,
            "pose_count": self.pose_count,
            "first_stamp_ns": self.first_stamp_ns,
            "last_stamp_ns": self.last_stamp_ns,
            "duration_s": round(self.duration_s, 6),
            "rate_hz": round(self.rate_hz, 3),
            "length_m": None if self.length_m is None else round(self.length_m, 3),
            "orientation": self.orientation,
            "indexed": self.indexed,
        }


@dataclass(frozen=True, slots=True)
class JointInspection:
    """One joint of a URDF file.

    Attributes:
        name: joint name.
        joint_type: ``fixed``, ``revolute``, ``continuous``, ...
        parent: parent link.
        child: child link.
    """

    name: str
    joint_type: str
    parent: str
    child: str

    def to_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict."""
        return {
            "name": self.name,
            "type": self.joint_type,
            "parent": self.parent,
            "child": self.child,
        }


@dataclass(frozen=True, slots=True)
class Inspection:
    """What an input holds and which trajectories can be read from it.

    Attributes:
        path: the inspected path, as given.
        kind: the input kind: a trajectory format (``tum``, ``euroc``, ``kitti``, ``csv``,
            ``motive``), a bag's storage format (``rosbag1``, ``rosbag2-sqlite3``,
            ``rosbag2-mcap``) or ``urdf``.
        format: the reader's format (``bag`` for every bag), ``urdf``, or ``anchors`` /
            ``ranges`` for the tables of a radio system.
        sources: the trajectory sources (for bags: pose topics first, then tf chains).
        warnings: what looked wrong or what the readers did (broken tf tree, sorted
            stamps, axis conversion).
        storage_format: for bags, the container format; else ``""``.
        archive: ``zip`` when the bag was inside a zip, else ``""``.
        start_ns: for bags, receive time of the first message (0 for an empty bag).
        end_ns: for bags, receive time of the last message.
        message_count: for bags, messages in the bag.
        topics: for bags, every topic, by name.
        frames: for bags, the tf tree, depth first.
        robot: for URDF files, the robot's name (``""`` when it has none).
        links: for URDF files, the link names in file order.
        joints: for URDF files, the joints in file order.
        trajectory_source: for files that hold one trajectory, its ``source`` text (the
            path as the reader names it).
        anchor_ids: for radio tables (format ``anchors`` or ``ranges``), the anchor ids.
        range_count: for a ranges table, its rows.
        point_ids: for control-point surveys, the ids in file order.
        extent_m: for control-point surveys, the x, y and z extent of the points, metres.
        visit_count: for visits tables, the visits (rows); their points are ``point_ids``
            and their time range ``start_ns`` to ``end_ns``.
    """

    path: str
    kind: str
    format: str
    sources: tuple[SourceInspection, ...]
    warnings: tuple[str, ...] = ()
    storage_format: str = ""
    archive: str = ""
    start_ns: int = 0
    end_ns: int = 0
    message_count: int = 0
    topics: tuple[TopicInspection, ...] = ()
    frames: tuple[FrameInspection, ...] = ()
    robot: str = ""
    links: tuple[str, ...] = ()
    joints: tuple[JointInspection, ...] = ()
    trajectory_source: str = ""
    anchor_ids: tuple[str, ...] = ()
    range_count: int = 0
    point_ids: tuple[str, ...] = ()
    extent_m: tuple[float, ...] = ()
    visit_count: int = 0

    @property
    def is_bag(self) -> bool:
        """Whether the input is a bag."""
        return self.format == "bag"

    @property
    def is_urdf(self) -> bool:
        """Whether the input is a URDF file."""
        return self.format == "urdf"

    @property
    def candidates(self) -> tuple[SourceInspection, ...]:
        """The trajectory sources (the name :func:`inspect_recording` callers use)."""
        return self.sources

    @property
    def single(self) -> SourceInspection | None:
        """The one trajectory of a file that holds exactly one (None for bags and URDF)."""
        if self.is_bag or self.is_urdf or len(self.sources) != 1:
            return None
        return self.sources[0]

    @property
    def duration_s(self) -> float:
        """Bags: first to last message; files with one trajectory: first to last pose."""
        if self.is_bag:
            return max(self.end_ns - self.start_ns, 0) / NS
        single = self.single
        return 0.0 if single is None else single.duration_s

    def to_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict (stamps as integer nanoseconds; keys per kind)."""
        out: dict[str, object] = {"path": self.path, "kind": self.kind, "format": self.format}
        if self.is_bag:
            out |= {
                "storage_format": self.storage_format,
                "archive": self.archive or None,
                "start_ns": self.start_ns,
                "end_ns": self.end_ns,
                "duration_s": round(self.duration_s, 6),
                "message_count": self.message_count,
                "topics": [t.to_dict() for t in self.topics],
                "tf_tree": [f.to_dict() for f in self.frames],
            }
        if self.format == "points":
            out |= {
                "points": len(self.point_ids),
                "ids": list(self.point_ids),
                "extent_m": list(self.extent_m),
            }
        if self.format == "visits":
            out |= {
                "visits": self.visit_count,
                "ids": list(self.point_ids),
                "start_s": self.start_ns / NS,
                "end_s": self.end_ns / NS,
            }
        if self.is_urdf:
            out |= {
                "robot": self.robot or None,
                "links": list(self.links),
                "joints": [j.to_dict() for j in self.joints],
            }
        if self.format == "anchors":
            out["anchors"] = list(self.anchor_ids)
        if self.format == "ranges":
            out |= {"ranges": self.range_count, "anchor_ids": list(self.anchor_ids)}
        single = self.single
        if single is not None and single.first_stamp_ns is not None:
            last = single.last_stamp_ns if single.last_stamp_ns is not None else 0
            out |= {
                "source": self.trajectory_source,
                "poses": single.pose_count,
                "start_s": single.first_stamp_ns / NS,
                "end_s": last / NS,
                "duration_s": single.duration_s,
                "length_m": single.length_m,
                "rate_hz": single.rate_hz,
                "orientation": single.orientation,
            }
        out["sources"] = [s.to_dict() for s in self.sources]
        out["warnings"] = list(self.warnings)
        return out
