"""The terminal text of an inspection (what ``loceval inspect`` prints without ``--json``)."""

from __future__ import annotations

import datetime as dt
from typing import Final

from loceval.core.quantities import ARROW, format_duration
from loceval.inspection.model import NS, Inspection, SourceInspection

__all__ = ["render_inspection_text"]

_EPOCH_2000_NS: Final = 946_684_800 * NS


def render_inspection_text(insp: Inspection) -> str:
    """Render an inspection for the terminal.

    Bags: the time range, topics, the tf tree with rates and the sources with their
    selectors. Files holding one trajectory: its summary (format, poses, time range,
    duration, length, rate, orientation). Motive takes: a source line per rigid body. URDF:
    links and joints. Radio tables: the anchors (and the ranges' count). Warnings last.
    """
    if insp.is_bag:
        lines = _bag_lines(insp)
    elif insp.is_urdf:
        lines = _urdf_lines(insp)
    elif insp.format in {"anchors", "ranges"}:
        count = f"{insp.range_count} ranges to " if insp.format == "ranges" else ""
        ids = ", ".join(insp.anchor_ids)
        lines = [f"{insp.path}  ({insp.format})", f"  {count}{len(insp.anchor_ids)} anchors: {ids}"]
    else:
        lines = _file_lines(insp)
    if insp.warnings:
        lines += ["", "warnings:"]
        lines.extend(f"  {w}" for w in insp.warnings)
    return "\n".join(lines)


def _bag_lines(insp: Inspection) -> list[str]:
    lines = [
        f"{insp.path}  ({insp.storage_format}{', zipped' if insp.archive else ''})",
        (
            f"  {insp.message_count} messages, {format_duration(insp.duration_s)}: "
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
    lines.extend(_source_lines(insp))
    if not insp.sources:
        lines.append("  (none: no pose topic of a supported type and no dynamic tf link)")
    return lines


def _file_lines(insp: Inspection) -> list[str]:
    lines = [f"{insp.path}  ({insp.kind})"]
    if insp.format == "visits":
        return [
            *lines,
            (
                f"  {insp.visit_count} visits of {len(insp.point_ids)} points, "
                f"{_stamp_text(insp.start_ns)} .. {_stamp_text(insp.end_ns)}"
            ),
            "",
            "trajectory sources: none (a visits table goes with a control-point reference)",
        ]
    if insp.format == "points":
        extent = " x ".join(f"{e:.3f}" for e in insp.extent_m)
        return [
            *lines,
            f"  {len(insp.point_ids)} control points over {extent} m: {', '.join(insp.point_ids)}",
            "",
            "trajectory sources: none (control points are a reference: points:FILE)",
        ]
    if insp.single is not None:
        return lines + [f"{key:>14}: {value}" for key, value in _summary(insp, insp.single)]
    lines += ["", "trajectory sources (type FILE@SELECTOR):"]
    lines.extend(_source_lines(insp))
    return lines


def _summary(insp: Inspection, single: SourceInspection) -> list[tuple[str, str]]:
    """The lines of a file holding one trajectory, as the bag listing words them."""
    rows = [("format", insp.format), ("source", insp.trajectory_source)]
    rows.append(("poses", f"{single.pose_count:,}"))
    if single.indexed:
        rows.append(
            ("times", "none: the poses are numbered (give the times file: kitti:FILE@times=TIMES)")
        )
    elif single.first_stamp_ns is not None:
        rows += [
            ("start", _stamp_text(single.first_stamp_ns)),
            ("end", _stamp_text(single.last_stamp_ns)),
            ("duration", format_duration(single.duration_s)),
            ("rate", f"{single.rate_hz:.1f} Hz"),
        ]
    if single.length_m is not None:
        rows.append(("path length", f"{single.length_m:.3f} m"))
    if single.orientation is not None:
        rows.append(("orientation", str(single.orientation)))
    return rows


def _source_lines(insp: Inspection) -> list[str]:
    selectors = [s.selector or "" for s in insp.sources]
    width = max((len(s) for s in selectors), default=0)
    lines = []
    for selector, s in zip(selectors, insp.sources, strict=True):
        rate = f"{s.rate_hz:7.1f} Hz" if s.rate_hz else " " * 10
        length = f"  {s.length_m:9.3f} m" if s.length_m is not None else ""
        lines.append(
            f"  {selector:<{width}}  {s.pose_count:>7} poses  {s.duration_s:9.2f} s  "
            f"{rate}{length}  {s.description}"
        )
    return lines


def _urdf_lines(insp: Inspection) -> list[str]:
    robot = f", robot {insp.robot!r}" if insp.robot else ""
    lines = [f"{insp.path}  (urdf{robot})", "", "links:"]
    lines.extend(f"  {link}" for link in insp.links)
    if not insp.links:
        lines.append("  (none)")
    lines += ["", "joints:"]
    lines.extend(f"  {j.name}  ({j.joint_type}): {j.parent} {ARROW} {j.child}" for j in insp.joints)
    if not insp.joints:
        lines.append("  (none)")
    lines += ["", "trajectory sources: none (a URDF describes the device, use it as offset)"]
    return lines


def _stamp_text(stamp_ns: int | None) -> str:
    """Render a stamp: ISO UTC for wall-clock stamps, seconds for simulation time."""
    if stamp_ns is None:
        return "-"
    if stamp_ns >= _EPOCH_2000_NS:
        when = dt.datetime.fromtimestamp(stamp_ns / NS, tz=dt.UTC)
        return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")
    return f"{stamp_ns / NS:.3f} s"
