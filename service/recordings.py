"""Recognise an uploaded recording and list the trajectories it holds.

The inspection is stored with the dataset, so the web page and API clients can offer the
sources (``selector``) without reading the file again. Reading a text trajectory fully here
also means a corrupt file is refused at upload with the reader's message, not at evaluation.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Final

from loceval.errors import ReaderError
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory, sniff_format
from loceval.trajectory import Trajectory

__all__ = ["inspect_upload"]

_NS: Final = 1_000_000_000
_DESCRIPTIONS: Final = {
    TrajectoryFormat.TUM: "TUM trajectory",
    TrajectoryFormat.EUROC: "EuRoC ground truth",
    TrajectoryFormat.KITTI: "KITTI poses",
    TrajectoryFormat.CSV: "CSV trajectory",
}


def inspect_upload(path: Path, filename: str) -> dict[str, Any]:
    """Return the kind of an uploaded file and the trajectory sources in it.

    Args:
        path: the file on disk.
        filename: the name the client gave (its suffix tells URDF and bags apart).

    Returns:
        ``{"kind", "format", "sources": [...], "warnings": [...]}`` plus, for bags, the
        topics and tf tree, and for URDF the links.

    Raises:
        ReaderError: the file is empty or not a recording loceval can read (the message
            says what was expected).
    """
    if path.stat().st_size == 0:
        msg = f"{filename!r} is empty; upload the recording itself."
        raise ReaderError(msg)
    suffix = Path(filename).suffix.lower()
    if suffix in {".urdf", ".xml"}:
        return _inspect_urdf(path, filename)
    fmt = sniff_format(path)
    if fmt is TrajectoryFormat.BAG:
        from loceval.inspection import inspect_recording  # noqa: PLC0415

        inspection = inspect_recording(path).to_dict()
        inspection.pop("path", None)
        kind = str(inspection["storage_format"])
        return {"kind": kind, "format": fmt.value, **inspection}
    if fmt is TrajectoryFormat.MOTIVE:
        from loceval.readers.motive import list_rigid_bodies  # noqa: PLC0415

        sources = []
        warnings: list[str] = []
        for body in list_rigid_bodies(path):
            trajectory = read_trajectory(SourceSpec(fmt, path, body), name=body)
            sources.append(_source(body, "rigid_body", f"Motive rigid body {body}", trajectory))
            warnings += [w.replace(str(path), filename) for w in trajectory.warnings]
        if not sources:
            msg = f"{filename!r}: no Rigid Body columns; export the take with rigid bodies."
            raise ReaderError(msg)
        return {"kind": fmt.value, "format": fmt.value, "sources": sources, "warnings": warnings}
    trajectory = read_trajectory(SourceSpec(fmt, path), name=Path(filename).stem)
    warnings = [w.replace(str(path), filename) for w in trajectory.warnings]
    if fmt is TrajectoryFormat.KITTI:
        warnings.append("KITTI poses without a times file: stamps are the pose index (1 s apart).")
    return {
        "kind": fmt.value,
        "format": fmt.value,
        "sources": [_source(None, "file", _DESCRIPTIONS[fmt], trajectory)],
        "warnings": warnings,
    }


def _source(selector: str | None, kind: str, description: str, t: Trajectory) -> dict[str, Any]:
    first, last = int(t.stamps_ns[0]), int(t.stamps_ns[-1])
    return {
        "selector": selector,
        "kind": kind,
        "description": description,
        "pose_count": len(t),
        "first_stamp_ns": first,
        "last_stamp_ns": last,
        "duration_s": round((last - first) / _NS, 6),
        "length_m": round(t.length_m, 3),
        "orientation": t.has_orientation,
    }


def _inspect_urdf(path: Path, filename: str) -> dict[str, Any]:
    try:
        root = ET.parse(path).getroot()  # noqa: S314  (expat refuses entity expansion bombs)
    except (ET.ParseError, OSError) as err:
        msg = f"{filename!r} is not readable XML ({err}); upload the robot's URDF."
        raise ReaderError(msg) from err
    if root.tag != "robot":
        msg = f"{filename!r} is XML but not a URDF (root <{root.tag}>, expected <robot>)."
        raise ReaderError(msg)
    links = [str(e.get("name")) for e in root.iter("link") if e.get("name")]
    joints = [
        {"name": e.get("name"), "parent": _link_of(e, "parent"), "child": _link_of(e, "child")}
        for e in root.iter("joint")
    ]
    return {
        "kind": "urdf",
        "format": "urdf",
        "robot": root.get("name"),
        "links": links,
        "joints": joints,
        "sources": [],
        "warnings": [],
    }


def _link_of(joint: ET.Element, tag: str) -> str | None:
    element = joint.find(tag)
    return None if element is None else element.get("link")
