"""What an input holds, and which trajectories can be read from it (``loceval inspect``).

:func:`inspect` describes every input kind loceval reads with one typed result,
:class:`Inspection`: trajectory files (TUM, EuRoC, KITTI, CSV), OptiTrack Motive takes (a
source per rigid body), ROS 1 bags, ROS 2 bags (sqlite3 or MCAP, folder or file, or zipped),
URDF files (links and joints) and the anchors and ranges tables of radio systems. The command
line prints it (:func:`render_inspection_text`, or ``to_dict()`` as JSON) and the service
stores it with an upload, so both describe a file the same way.

Each input kind has an entry in :data:`INSPECTORS` whose module is imported on first use,
so importing this package loads neither rosbags nor the readers of other kinds.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Final, cast

from loceval.errors import InputError
from loceval.inspection.model import (
    FrameInspection,
    Inspection,
    JointInspection,
    SourceInspection,
    TopicInspection,
)
from loceval.inspection.render import render_inspection_text
from loceval.readers.sniff import sniff_format
from loceval.readers.source import (
    SourceSpec,
    TrajectoryFormat,
    parse_source,
    refuse_special_file,
)

__all__ = [
    "INSPECTORS",
    "URDF_SUFFIXES",
    "FrameInspection",
    "Inspection",
    "InspectorSpec",
    "JointInspection",
    "SourceInspection",
    "TopicInspection",
    "format_inspection",
    "input_kind",
    "inspect",
    "inspect_recording",
    "render_inspection_text",
]

Inspector = Callable[[SourceSpec], Inspection]
"""``(source) -> Inspection``; the source's format is set for trajectory formats."""

URDF_SUFFIXES: Final = (".urdf", ".xml")
"""File name endings that mark a URDF file (URDF is XML; it is not sniffed from content)."""


@dataclass(frozen=True, slots=True)
class InspectorSpec:
    """How one input kind is inspected.

    Attributes:
        kind: the registry key (a :class:`~loceval.readers.TrajectoryFormat` value or
            ``urdf``).
        description: what the input is, in words.
        target: ``"module:function"`` of the inspector, imported on first use.
    """

    kind: str
    description: str
    target: str

    def load(self) -> Inspector:
        """Import and return the inspector function."""
        module_name, _, func_name = self.target.partition(":")
        module = importlib.import_module(module_name)
        return cast("Inspector", getattr(module, func_name))


_FILES: Final = "loceval.inspection.files"

INSPECTORS: Final[Mapping[str, InspectorSpec]] = MappingProxyType(
    {
        spec.kind: spec
        for spec in (
            InspectorSpec("tum", "TUM trajectory", f"{_FILES}:inspect_trajectory_file"),
            InspectorSpec("euroc", "EuRoC ground truth", f"{_FILES}:inspect_trajectory_file"),
            InspectorSpec("kitti", "KITTI poses", f"{_FILES}:inspect_trajectory_file"),
            InspectorSpec("csv", "CSV trajectory", f"{_FILES}:inspect_trajectory_file"),
            InspectorSpec("motive", "OptiTrack Motive take", f"{_FILES}:inspect_motive"),
            InspectorSpec(
                "bag",
                "ROS 1 bag, ROS 2 bag (sqlite3 or MCAP) or a zip of one",
                "loceval.inspection.bag:inspect_bag",
            ),
            InspectorSpec("points", "surveyed control points", f"{_FILES}:inspect_points"),
            InspectorSpec("visits", "visits of control points", f"{_FILES}:inspect_visits"),
            InspectorSpec(
                "urdf", "URDF robot description", "loceval.inspection.robot:inspect_urdf"
            ),
            InspectorSpec(
                "anchors", "radio anchors (id,x,y,z)", "loceval.inspection.radio:inspect_anchors"
            ),
            InspectorSpec(
                "ranges",
                "radio ranges (t,anchor_id,range_m)",
                "loceval.inspection.radio:inspect_ranges",
            ),
        )
    }
)
"""The inspector of every input kind, by kind."""


def input_kind(spec: SourceSpec) -> str:
    """Return the :data:`INSPECTORS` key of a source.

    The format prefix wins; else a ``.urdf`` or ``.xml`` name is URDF; else a ranges table
    is told by its header (:func:`loceval.readers.radio.sniff_radio_table`); else the format
    is sniffed from the content (:func:`loceval.readers.sniff_format`): a survey ``id,x,y,z``
    is ``points`` (control points, or a radio system's anchors), and a CSV whose header is
    ``id,t_start,t_end`` is a visits table (``visits``).

    Raises:
        ReaderError: the path does not exist or its content matches no format.
    """
    if spec.format is not None:
        return spec.format.value
    if spec.path.suffix.lower() in URDF_SUFFIXES and not spec.path.is_dir():
        return "urdf"
    if spec.path.is_file():
        from loceval.readers.radio import sniff_radio_table  # noqa: PLC0415

        if sniff_radio_table(spec.path) == "ranges":
            return "ranges"
    fmt = sniff_format(spec.path)
    if fmt is TrajectoryFormat.CSV and _is_visits_table(spec.path):
        return "visits"
    return fmt.value


def _is_visits_table(path: Path) -> bool:
    """Whether a CSV's first row is a visits header ``id,t_start,t_end``."""
    from loceval.readers.points import looks_like_visits  # noqa: PLC0415

    with path.open(encoding="utf-8-sig", errors="replace") as fh:
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                return looks_like_visits(line)
    return False


def inspect(source: str | Path | SourceSpec, *, kind: str | None = None) -> Inspection:
    """Describe an input and list the trajectories that can be read from it.

    Args:
        source: ``[FORMAT:]PATH[@SELECTOR]`` text, a path (taken literally), or a parsed
            source. A Motive selector limits the inspection to that rigid body; options
            (KITTI ``times``, CSV columns, Motive ``up``) are used as for reading; a bag's
            selector is not used (the whole bag is described).
        kind: an :data:`INSPECTORS` key that overrides detection (e.g. ``urdf`` for a file
            whose name does not say so); None detects it (:func:`input_kind`).

    Returns:
        The inspection.

    Raises:
        InputError: ``kind`` is not a known input kind.
        ReaderError: the input is missing, unreadable, or matches no format.
    """
    if isinstance(source, SourceSpec):
        spec = source
    elif isinstance(source, Path):
        spec = SourceSpec(None, source)
    else:
        spec = parse_source(source)
    refuse_special_file(spec.path)
    key = kind or input_kind(spec)
    entry = INSPECTORS.get(key)
    if entry is None:
        msg = f"Unknown input kind {key!r}; use one of {', '.join(INSPECTORS)}."
        raise InputError(msg)
    if key in {f.value for f in TrajectoryFormat}:
        spec = SourceSpec(TrajectoryFormat(key), spec.path, spec.selector, spec.options)
    return entry.load()(spec)


def inspect_recording(path: Path) -> Inspection:
    """Describe a bag (a ROS 1 bag, ROS 2 bag folder, ``.mcap``/``.db3`` file or zip of one).

    Raises:
        ReaderError: the bag cannot be read.
    """
    return inspect(SourceSpec(TrajectoryFormat.BAG, Path(path)))


format_inspection = render_inspection_text
"""The terminal text of an inspection (the name bag-only callers know)."""
