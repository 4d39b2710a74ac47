"""Inspect a bag: topics, the tf tree with rates, and the trajectory sources.

Reads the bag's index and metadata, its tf messages and the first and last message of each
pose topic, never image or point-cloud payloads (:func:`loceval.readers.rosbag.read_bag_overview`),
and lists the trajectory sources with the selector to type (``FILE@SELECTOR``): pose topics
of a supported type, and tf chains (for every dynamic link, its parent -> child, the chain
from its tree's root, and REP 105 pairs such as ``map -> base_link``).

The tf sources are listed most useful first (:func:`_usefulness`): chains from a fixed frame
(``earth``, ``world``, ``map``, ``odom``, or a tree's root) to a robot or device frame (a
``base_link``/``base_footprint``, or a frame hung directly from a fixed frame, as a tracked
rigid body is), then chains from a fixed frame to a part of the robot (wheels, sensors),
then between two fixed frames (``map -> odom``), then links inside the robot
(``base_link -> left_wheel``). Within each group: the fixed frames in the order above,
``base_link`` before ``base_footprint``, frames nearer the root first, then by name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loceval.errors import ReaderError
from loceval.inspection.model import (
    NS,
    FrameInspection,
    Inspection,
    SourceInspection,
    TopicInspection,
)
from loceval.readers import SourceSpec
from loceval.readers.rosbag import PoseKind, RemoteFile, TopicOverview, read_bag_overview
from loceval.readers.tftree import TfBuffer, compose_chain, describe_chain, find_chain

__all__ = ["inspect_bag", "inspect_bag_file"]

_WORLD_FRAMES = ("earth", "world", "map", "odom")
_BODY_FRAMES = ("base_link", "base_footprint")


def inspect_bag(spec: SourceSpec) -> Inspection:
    """Describe a bag and list the trajectories that can be read from it.

    Args:
        spec: the bag (a ROS 1 bag, a ROS 2 bag directory, an ``.mcap`` or ``.db3`` file,
            or a ``.zip`` of one); its selector is not used.

    Returns:
        The inspection (``kind`` is the storage format, ``format`` is ``bag``).

    Raises:
        ReaderError: the bag cannot be read.
    """
    return inspect_bag_file(spec.path)


def inspect_bag_file(path: Path | RemoteFile) -> Inspection:
    """Describe a bag file (see :func:`inspect_bag`), also one read by position from a store.

    Raises:
        ReaderError: the bag cannot be read.
    """
    overview = read_bag_overview(path)
    warnings: list[str] = []
    topics = tuple(
        TopicInspection(t.name, t.msgtype, t.message_count, pose_source=_is_pose_topic(t))
        for t in overview.topics
    )
    sources = [
        _topic_source(t) for t in overview.topics if _is_pose_topic(t) and t.message_count > 0
    ]
    frames = _frames(overview.tf, warnings)
    depths = {f.frame: f.depth for f in frames}
    tf_sources = _tf_candidates(overview.tf, warnings)
    sources.extend(
        sorted(tf_sources, key=lambda x: _usefulness(overview.tf, depths, str(x.selector)))
    )
    return Inspection(
        path=str(path),
        kind=str(overview.storage_format),
        format="bag",
        sources=tuple(sources),
        warnings=tuple(warnings),
        storage_format=str(overview.storage_format),
        archive=overview.archive,
        start_ns=overview.start_ns,
        end_ns=overview.end_ns,
        message_count=overview.message_count,
        topics=topics,
        frames=frames,
    )


def _is_pose_topic(topic: TopicOverview) -> bool:
    return topic.kind is not None and topic.kind is not PoseKind.TF


def _topic_source(topic: TopicOverview) -> SourceInspection:
    first, last = topic.first_stamp_ns, topic.last_stamp_ns
    span_ns = 0 if first is None or last is None else last - first
    rate_hz = (topic.pose_count - 1) * NS / span_ns if span_ns > 0 else 0.0
    return SourceInspection(
        topic.name,
        "topic",
        topic.msgtype,
        topic.pose_count,
        first,
        last,
        rate_hz=rate_hz,
        orientation=topic.kind is not PoseKind.POINT,
    )


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


def _tf_candidates(buffer: TfBuffer, warnings: list[str]) -> list[SourceInspection]:
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
    out: list[SourceInspection] = []
    seen: set[tuple[str, str]] = set()
    for parent, child in pairs:
        if (parent, child) in seen or parent == child:
            continue
        seen.add((parent, child))
        candidate = _tf_candidate(buffer, parent, child, warnings)
        if candidate is not None:
            out.append(candidate)
    return out


def _usefulness(
    buffer: TfBuffer, depths: dict[str, int], selector: str
) -> tuple[int, int, int, int, str, str]:
    """Return the sort key of a ``tf:PARENT:CHILD`` source: smaller is more useful.

    Args:
        buffer: the bag's tf links.
        depths: each frame's depth in its tree (0 for a root).
        selector: the source's ``tf:PARENT:CHILD`` selector.

    Returns:
        ``(group, fixed-frame rank, body-frame rank, depth, parent, child)``: group 0 is a
        fixed frame -> a robot or device frame, 1 a fixed frame -> a part of the robot, 2 a
        fixed frame -> a fixed frame, 3 a chain inside the robot.
    """
    _, parent, child = selector.split(":", 2)
    roots = set(buffer.roots())

    def fixed(frame: str) -> bool:
        return frame in _WORLD_FRAMES or frame in roots

    def rank(frame: str, names: tuple[str, ...]) -> int:
        return names.index(frame) if frame in names else len(names)

    if not fixed(parent):
        group = 3
    elif fixed(child):
        group = 2
    elif child in _BODY_FRAMES or all(fixed(x.parent) for x in buffer.parent_links(child)):
        group = 0
    else:
        group = 1
    return (
        group,
        rank(parent, _WORLD_FRAMES),
        rank(child, _BODY_FRAMES),
        depths.get(child, 0),
        parent,
        child,
    )


def _tf_candidate(
    buffer: TfBuffer, parent: str, child: str, warnings: list[str]
) -> SourceInspection | None:
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
    steps_ns = np.diff(stamps)
    median_ns = float(np.median(steps_ns)) if steps_ns.size else 0.0
    return SourceInspection(
        f"tf:{parent}:{child}",
        "tf",
        describe_chain(steps),
        int(stamps.shape[0]),
        None if empty else int(stamps[0]),
        None if empty else int(stamps[-1]),
        rate_hz=NS / median_ns if median_ns > 0 else 0.0,
        orientation=True,
    )
