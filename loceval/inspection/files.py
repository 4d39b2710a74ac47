"""Inspect trajectory files: TUM, EuRoC, KITTI, generic CSV, and OptiTrack Motive takes.

A file is read whole through :func:`loceval.readers.read_trajectory` (so a corrupt file is
refused here with the reader's message), and each trajectory it holds becomes one source:
the file itself, or one per rigid body of a Motive take.
"""

from __future__ import annotations

from typing import Final

from loceval.errors import ReaderError
from loceval.inspection.model import Inspection, SourceInspection
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory
from loceval.readers.motive import list_rigid_bodies
from loceval.trajectory import Trajectory

__all__ = [
    "inspect_motive",
    "inspect_points",
    "inspect_trajectory_file",
    "inspect_visits",
    "trajectory_source",
]

_DESCRIPTIONS: Final = {
    TrajectoryFormat.TUM: "TUM trajectory",
    TrajectoryFormat.EUROC: "EuRoC ground truth",
    TrajectoryFormat.KITTI: "KITTI poses",
    TrajectoryFormat.CSV: "CSV trajectory",
}


def inspect_trajectory_file(spec: SourceSpec) -> Inspection:
    """Describe a TUM, EuRoC, KITTI or CSV file: its one trajectory.

    Args:
        spec: the file with its format set; its options (KITTI times, CSV columns) are
            used as for reading.

    Returns:
        The inspection with one source (selector None, kind ``file``).

    Raises:
        ReaderError: the reader refuses the file (the message says why and what to do).
    """
    fmt = _format_of(spec)
    trajectory = read_trajectory(spec)
    return Inspection(
        path=str(spec.path),
        kind=fmt.value,
        format=fmt.value,
        sources=(trajectory_source(None, "file", _DESCRIPTIONS[fmt], trajectory),),
        warnings=trajectory.warnings,
        trajectory_source=trajectory.source,
    )


def inspect_motive(spec: SourceSpec) -> Inspection:
    """Describe a Motive take: one source per rigid body (or the one its selector names).

    Args:
        spec: the take; a selector limits the inspection to that rigid body, the ``up``
            option is used as for reading.

    Returns:
        The inspection with a source per rigid body (kind ``rigid_body``).

    Raises:
        ReaderError: the file is not a Motive export, has no rigid body, or a body's
            columns cannot be read.
    """
    bodies = [spec.selector] if spec.selector else list_rigid_bodies(spec.path)
    if not bodies:
        msg = (
            f"Motive take {str(spec.path)!r} has no Rigid Body columns; export the take "
            "with rigid bodies included."
        )
        raise ReaderError(msg)
    sources: list[SourceInspection] = []
    warnings: dict[str, None] = {}
    trajectories: list[Trajectory] = []
    for body in bodies:
        body_spec = SourceSpec(TrajectoryFormat.MOTIVE, spec.path, body, spec.options)
        trajectory = read_trajectory(body_spec, name=body)
        trajectories.append(trajectory)
        sources.append(
            trajectory_source(body, "rigid_body", f"Motive rigid body {body}", trajectory)
        )
        warnings.update(dict.fromkeys(trajectory.warnings))
    return Inspection(
        path=str(spec.path),
        kind=TrajectoryFormat.MOTIVE.value,
        format=TrajectoryFormat.MOTIVE.value,
        sources=tuple(sources),
        warnings=tuple(warnings),
        trajectory_source=trajectories[0].source if len(trajectories) == 1 else "",
    )


def inspect_points(spec: SourceSpec) -> Inspection:
    """Describe a control-point survey: its point ids and their extent (no trajectory).

    Raises:
        ReaderError: the reader refuses the survey (duplicate ids, too few points, ...).
    """
    from loceval.readers.points import read_control_points  # noqa: PLC0415

    points = read_control_points(spec.path)
    extent = points.positions_xyz.max(axis=0) - points.positions_xyz.min(axis=0)
    return Inspection(
        path=str(spec.path),
        kind=TrajectoryFormat.POINTS.value,
        format=TrajectoryFormat.POINTS.value,
        sources=(),
        warnings=points.warnings,
        point_ids=points.ids,
        extent_m=tuple(float(e) for e in extent),
    )


def inspect_visits(spec: SourceSpec) -> Inspection:
    """Describe a visits table: the points visited and the time range (no trajectory).

    Raises:
        ReaderError: the reader refuses the table (a missing column, a non-number, ...).
    """
    from loceval.readers.points import read_visit_table  # noqa: PLC0415

    ids, start_s, end_s = read_visit_table(spec.path)
    return Inspection(
        path=str(spec.path),
        kind="visits",
        format="visits",
        sources=(),
        point_ids=tuple(dict.fromkeys(ids)),
        visit_count=len(ids),
        start_ns=round(float(start_s.min()) * 1e9),
        end_ns=round(float(end_s.max()) * 1e9),
    )


def trajectory_source(
    selector: str | None, kind: str, description: str, trajectory: Trajectory
) -> SourceInspection:
    """Describe a trajectory that was read: count, time range, rate, length, orientation."""
    return SourceInspection(
        selector,
        kind,
        description,
        len(trajectory),
        int(trajectory.stamps_ns[0]),
        int(trajectory.stamps_ns[-1]),
        rate_hz=trajectory.rate_hz,
        length_m=trajectory.length_m,
        orientation=trajectory.has_orientation,
        indexed=trajectory.indexed,
    )


def _format_of(spec: SourceSpec) -> TrajectoryFormat:
    if spec.format is None or spec.format not in _DESCRIPTIONS:
        msg = (
            f"{str(spec.path)!r} is not a TUM, EuRoC, KITTI or CSV source ({spec.format}); "
            "name its format with a prefix, e.g. tum:FILE."
        )
        raise ReaderError(msg)
    return spec.format
