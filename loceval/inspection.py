"""What is in a bag, and which trajectories can be read from it (``loceval inspect``).

:func:`inspect_recording` reads a bag's index and metadata, its tf messages and the first
and last message of each pose topic, never image or point-cloud payloads, and lists the
trajectory sources with the selector to type (``FILE@SELECTOR``): pose topics of a
supported type, and tf chains (for every dynamic link, its parent -> child, the chain from
its tree's root, and REP 105 pairs such as ``map -> base_link``).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

from loceval.errors import ReaderError
from loceval.tftree import TfBuffer, compose_chain, describe_chain, find_chain

__all__ = [
    "FrameInspection",
    "RecordingInspection",
    "SourceCandidate",
    "TopicInspection",
    "format_inspection",
    "inspect_recording",
]

_NS = 1_000_000_000
_WORLD_FRAMES = ("earth", "world", "map", "odom")
_BODY_FRAMES = ("base_link", "base_footprint")
_EPOCH_2000_NS = 946_684_800 * _NS


@dataclass(frozen=True, slots=True)
class TopicInspection:
    """One topic.

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
    """One frame of the tf tree, in depth-first order.

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
class SourceCandidate:
    """A trajectory that can be read from the bag.

    Attributes:
        selector: what to type after ``FILE@``: a topic or ``tf:PARENT:CHILD``.
        kind: ``topic`` or ``tf``.
        description: the message type, or the tf chain (``map -> odom -> base_link``).
        pose_count: poses (for tf chains after dropping uncovered stamps; for topics the
            message count, or a Path's last message's poses).
        first_stamp_ns: first pose's header stamp, or None when unknown.
        last_stamp_ns: last pose's header stamp, or None when unknown.
    """

    selector: str
    kind: str
    description: str
    pose_count: int
    first_stamp_ns: int | None
    last_stamp_ns: int | None

    @property
    def duration_s(self) -> float:
        """Time from the first to the last pose in seconds (0 when unknown)."""
        if self.first_stamp_ns is None or self.last_stamp_ns is None:
            return 0.0
        return (self.last_stamp_ns - self.first_stamp_ns) / _NS

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
        }


@dataclass(frozen=True, slots=True)
class RecordingInspection:
    """The result of :func:`inspect_recording`.

    Attributes:
        path: the inspected path, as given.
        storage_format: ``rosbag1``, ``rosbag2-sqlite3`` or ``rosbag2-mcap``.
        archive: ``zip`` when the bag was inside a zip, else ``""``.
        start_ns: receive time of the first message (0 for an empty bag).
        end_ns: receive time of the last message.
        message_count: messages in the bag.
        topics: every topic, by name.
        frames: the tf tree, depth first.
        candidates: the trajectory sources, pose topics first.
        warnings: what looked wrong (broken tf tree, unreadable chains).
    """

    path: str
    storage_format: str
    archive: str
    start_ns: int
    end_ns: int
    message_count: int
    topics: tuple[TopicInspection, ...]
    frames: tuple[FrameInspection, ...]
    candidates: tuple[SourceCandidate, ...]
    warnings: tuple[str, ...]

    @property
    def duration_s(self) -> float:
        """Time from the first to the last message in seconds."""
        return max(self.end_ns - self.start_ns, 0) / _NS

    def to_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict (stamps as integer nanoseconds)."""
        return {
            "path": self.path,
            "storage_format": self.storage_format,
            "archive": self.archive or None,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "duration_s": round(self.duration_s, 6),
            "message_count": self.message_count,
            "topics": [t.to_dict() for t in self.topics],
            "tf_tree": [f.to_dict() for f in self.frames],
            "sources": [c.to_dict() for c in self.candidates],
            "warnings": list(self.warnings),
        }


def inspect_recording(path: Path) -> RecordingInspection:
    """Describe a bag and list the trajectories that can be read from it.

    Args:
        path: a ROS 1 bag, a ROS 2 bag directory, an ``.mcap`` or ``.db3`` file, or a
            ``.zip`` of one.

    Returns:
        The inspection.

    Raises:
        ReaderError: the bag cannot be read.
    """
    # Imported here so that importing this module (e.g. for format_inspection) does not
    # load rosbags.
    from loceval.readers.rosbag import read_bag_overview  # noqa: PLC0415

    overview = read_bag_overview(path)
    warnings: list[str] = []
    topics = tuple(
        TopicInspection(
            t.name,
            t.msgtype,
            t.message_count,
            pose_source=t.kind is not None and t.kind != "tf",
        )
        for t in overview.topics
    )
    candidates = [
        SourceCandidate(
            t.name,
            "topic",
            t.msgtype,
            t.pose_count,
            t.first_stamp_ns,
            t.last_stamp_ns,
        )
        for t in overview.topics
        if t.kind is not None and t.kind != "tf" and t.message_count > 0
    ]
    frames = _frames(overview.tf, warnings)
    candidates.extend(_tf_candidates(overview.tf, warnings))
    return RecordingInspection(
        path=str(path),
        storage_format=str(overview.storage_format),
        archive=overview.archive,
        start_ns=overview.start_ns,
        end_ns=overview.end_ns,
        message_count=overview.message_count,
        topics=topics,
        frames=frames,
        candidates=tuple(candidates),
        warnings=tuple(warnings),
    )


def format_inspection(insp: RecordingInspection) -> str:
    """Render an inspection for the terminal."""
    lines = [
        f"{insp.path}  ({insp.storage_format}{', zipped' if insp.archive else ''})",
        (
            f"  {insp.message_count} messages, {insp.duration_s:.3f} s: "
            f"{_stamp_text(insp.start_ns)} .. {_stamp_text(insp.end_ns)}"
        ),
        "",
        "topics:",
    ]
    width = max((len(t.name) for t in insp.topics), default=0)
    type_width = max((len(t.msgtype) for t in insp.topics), default=0)
    lines.extend(
        f"  {t.name:<{width}}  {t.msgtype:<{type_width}}  {t.message_count:>8}"
        f"{'  (pose)' if t.pose_source else ''}"
        for t in insp.topics
    )
    if not insp.topics:
        lines.append("  (none)")
    lines += ["", "tf tree:"]
    for f in insp.frames:
        indent = "  " * (f.depth + 1)
        if not f.parent:
            lines.append(f"{indent}{f.frame}")
        elif f.static:
            lines.append(f"{indent}{f.frame}  (static)")
        else:
            lines.append(
                f"{indent}{f.frame}  ({f.rate_hz:.1f} Hz, {f.message_count} transforms, "
                f"{_stamp_text(f.first_stamp_ns)} .. {_stamp_text(f.last_stamp_ns)})"
            )
    if not insp.frames:
        lines.append("  (no tf data)")
    lines += ["", "trajectory sources (type FILE@SELECTOR):"]
    sel_width = max((len(c.selector) for c in insp.candidates), default=0)
    lines.extend(
        f"  {c.selector:<{sel_width}}  {c.pose_count:>7} poses  {c.duration_s:9.2f} s  "
        f"{c.description}"
        for c in insp.candidates
    )
    if not insp.candidates:
        lines.append("  (none: no pose topic of a supported type and no dynamic tf link)")
    if insp.warnings:
        lines += ["", "warnings:"]
        lines.extend(f"  {w}" for w in insp.warnings)
    return "\n".join(lines)


def _frames(buffer: TfBuffer, warnings: list[str]) -> tuple[FrameInspection, ...]:
    children: dict[str, list[str]] = {}
    for link in buffer.links:
        children.setdefault(link.parent, []).append(link.child)
    out: list[FrameInspection] = []
    visited: set[str] = set()

    def visit(frame: str, parent: str, depth: int) -> None:
        if frame in visited:
            return
        visited.add(frame)
        link = buffer.link(parent, frame) if parent else None
        if link is None:
            out.append(
                FrameInspection(
                    frame,
                    "",
                    depth,
                    static=False,
                    rate_hz=0.0,
                    message_count=0,
                    first_stamp_ns=None,
                    last_stamp_ns=None,
                )
            )
        else:
            out.append(
                FrameInspection(
                    frame,
                    parent,
                    depth,
                    link.is_static,
                    link.rate_hz,
                    link.message_count,
                    int(link.stamps_ns[0]),
                    int(link.stamps_ns[-1]),
                )
            )
        for child in sorted(children.get(frame, [])):
            visit(child, frame, depth + 1)

    for root in buffer.roots():
        visit(root, "", 0)
    for frame in buffer.frames():
        parents = buffer.parent_links(frame)
        if len(parents) > 1:
            names = ", ".join(sorted(x.parent for x in parents))
            warnings.append(
                f"tf frame {frame!r} has {len(parents)} parents ({names}); chains through it "
                "cannot be read."
            )
    unvisited = [f for f in buffer.frames() if f not in visited]
    if unvisited:
        warnings.append(
            f"tf frames without a root (a loop?): {', '.join(unvisited)}; chains through them "
            "cannot be read."
        )
    return tuple(out)


def _tf_candidates(buffer: TfBuffer, warnings: list[str]) -> list[SourceCandidate]:
    pairs: list[tuple[str, str]] = []
    for link in sorted(buffer.links, key=lambda x: (x.parent, x.child)):
        if link.is_static:
            continue
        pairs.append((link.parent, link.child))
        try:
            root = buffer.root_of(link.child)
        except ReaderError:
            continue
        pairs.append((root, link.child))
    frames = set(buffer.frames())
    pairs.extend(
        (world, body)
        for world in _WORLD_FRAMES
        for body in _BODY_FRAMES
        if world in frames and body in frames
    )
    out: list[SourceCandidate] = []
    seen: set[tuple[str, str]] = set()
    for parent, child in pairs:
        if (parent, child) in seen or parent == child:
            continue
        seen.add((parent, child))
        candidate = _tf_candidate(buffer, parent, child, warnings)
        if candidate is not None:
            out.append(candidate)
    return out


def _tf_candidate(
    buffer: TfBuffer, parent: str, child: str, warnings: list[str]
) -> SourceCandidate | None:
    try:
        steps = find_chain(buffer, parent, child)
    except ReaderError:
        return None  # different trees, or a broken tree (reported with the frames)
    if all(s.link.is_static for s in steps):
        return None
    try:
        chain = compose_chain(buffer, parent, child)
    except ReaderError as err:
        warnings.append(f"tf:{parent}:{child}: {err}")
        return None
    stamps = chain.stamps_ns
    empty = stamps.shape[0] == 0
    return SourceCandidate(
        f"tf:{parent}:{child}",
        "tf",
        describe_chain(steps),
        int(stamps.shape[0]),
        None if empty else int(stamps[0]),
        None if empty else int(stamps[-1]),
    )


def _stamp_text(stamp_ns: int | None) -> str:
    """Render a stamp: ISO UTC for wall-clock stamps, seconds for simulation time."""
    if stamp_ns is None:
        return "-"
    if stamp_ns >= _EPOCH_2000_NS:
        when = dt.datetime.fromtimestamp(stamp_ns / _NS, tz=dt.UTC)
        return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")
    return f"{stamp_ns / _NS:.3f} s"
