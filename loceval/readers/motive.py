"""Reader for OptiTrack Motive CSV exports (format versions 1.2x, Motive 2 and 3).

The export is parsed by its row labels, not by fixed line numbers: the first line holds
``key,value`` pairs (``Format Version``, ``Capture Start Time``, ``Rotation Type``,
``Length Units``, ``Coordinate Space``, ...); then rows labelled ``Type``, ``Name``, ``ID``
(and ``Parent`` in some versions), an unlabelled row naming each column's quantity
(``Rotation``, ``Position``, ``Mean Marker Error``), and the ``Frame,Time (Seconds),X,Y,...``
row; the frames follow. Only ``Rigid Body`` columns are read (not markers or bones), by
their labels, so any column order works.

Conventions:

- **Units**: ``Length Units`` Meters, Centimeters or Millimeters become metres.
- **Axes**: Motive's default world is right-handed and Y-up; REP 103 is Z-up. The reader
  rotates the world by +90° about x, ``C = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]``, so
  ``(x, y, z) -> (x, -z, y)``: Motive's up axis +Y becomes +Z and +X stays +X. Positions map
  as ``C p`` and orientations as ``C R`` (a change of the world frame only; the rigid body's
  own axes are kept as defined in Motive). Exports already made Z-up (an ``Up Axis`` key in
  the header, or ``up_axis="z"``) are not rotated. The result's warnings say which applied.
- **Time**: ``Time (Seconds)`` is added to ``Capture Start Time`` read as UTC (Motive does
  not store the time zone; a warning says so); without a readable start time the stamps
  are seconds since the start of the take.
- **Tracking loss**: frames where a used cell of the rigid body is empty are dropped and
  counted in a warning.
"""

from __future__ import annotations

import calendar
import io
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Final

import numpy as np

from loceval.core.geometry import SimilarityTransform
from loceval.errors import ReaderError
from loceval.readers._common import build_trajectory
from loceval.readers.source import SourceSpec, TrajectoryFormat
from loceval.readers.text import csv_rows, load_text, parse_table, stamps_from_values
from loceval.trajectory import Trajectory

__all__ = ["MOTIVE_FRAME_ID", "Y_UP_TO_Z_UP", "list_rigid_bodies", "read_motive"]

MOTIVE_FRAME_ID: Final = "motive_world"
"""The ``frame_id`` of trajectories read from Motive exports."""

Y_UP_TO_Z_UP: Final = SimilarityTransform(
    np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]), np.zeros(3)
)
"""+90° about x: maps Motive's Y-up world to REP 103 Z-up, ``(x, y, z) -> (x, -z, y)``."""

_LENGTH_UNITS: Final[Mapping[str, float]] = {
    "meters": 1.0,
    "centimeters": 0.01,
    "millimeters": 0.001,
}
_START_TIME_FORMATS: Final = (
    "%Y-%m-%d %I.%M.%S.%f %p",
    "%Y-%m-%d %I.%M.%S %p",
    "%Y-%m-%d %H.%M.%S.%f",
    "%Y-%m-%d %H.%M.%S",
    "%Y-%m-%d %I:%M:%S.%f %p",
    "%Y-%m-%d %H:%M:%S.%f",
    "%Y-%m-%d %H:%M:%S",
)
_HEADER_SEARCH_LINES: Final = 64
_LABELS: Final = ("Type", "Name", "ID", "Parent")
_QUANTITIES: Final = ("Rotation", "Position")
_NS_PER_S: Final = 1_000_000_000


@dataclass(frozen=True, slots=True)
class _Layout:
    """What the header rows say."""

    meta: dict[str, str]
    labels: dict[str, list[str]]  # label -> cell per column
    quantities: list[str]  # Rotation / Position / ... per column
    axes: list[str]  # the Frame row: Frame, Time (Seconds), X, Y, ...
    frame_line: int  # 0-based index of the Frame row


def list_rigid_bodies(path: Path) -> list[str]:
    """Return the names of the rigid bodies in a Motive export, in column order.

    Raises:
        ReaderError: the file is missing or not a Motive export.
    """
    path = Path(path)
    return _rigid_bodies(_read_layout(load_text(path), where=str(path)))


def read_motive(
    path: Path,
    *,
    rigid_body: str | None = None,
    up_axis: str | None = None,
    name: str = "",
) -> Trajectory:
    """Read one rigid body from an OptiTrack Motive CSV export (see the module docstring).

    Args:
        path: the export.
        rigid_body: the rigid body's name; None when the export holds exactly one.
        up_axis: ``"y"`` (Motive's default; rotated to Z-up) or ``"z"`` (kept as is); None
            to take it from an ``Up Axis`` header key, else ``"y"``.
        name: the trajectory's name.

    Returns:
        The trajectory in metres and REP 103 axes; ``frame_id`` is ``motive_world``,
        ``child_frame_id`` the rigid body, ``source`` ``motive:PATH@BODY``.

    Raises:
        ReaderError: the file is missing or not a Motive export, the rigid body is not
            named or not in it (the message lists those that are), rotations are Euler
            angles, the length unit is unknown, a cell is not a number, a quaternion is
            not unit, or fewer than three tracked frames remain.
    """
    path = Path(path)
    where = str(path)
    text = load_text(path)
    layout = _read_layout(text, where=where)
    bodies = _rigid_bodies(layout)
    body = _pick_body(bodies, rigid_body, path=path)
    time_col, position_cols, rotation_cols = _body_columns(layout, body, where=where)
    up = _up_axis(layout.meta, up_axis, where=where)
    scale = _length_scale(layout.meta, where=where)
    notes: list[str] = []
    if scale is None:
        notes.append(f"{where}: no Length Units in the header; positions read as metres.")
        scale = 1.0
    if layout.meta.get("Coordinate Space", "Global").strip().lower() == "local":
        notes.append(
            f"{where}: Coordinate Space is Local, so poses are relative to each body's "
            "parent; re-export with Global coordinates for world poses."
        )
    usecols = [time_col, *position_cols, *rotation_cols]
    names = [layout.axes[time_col]] + [
        f"{body} {_cell(layout.quantities, c)} {_cell(layout.axes, c)}" for c in usecols[1:]
    ]
    table = parse_table(
        text,
        where=where,
        delimiter=",",
        hint="every frame row needs the rigid body's cells",
        skip_lines=layout.frame_line + 1,
        usecols=usecols,
        names=names,
        empty_cells=True,
    )
    total = len(table)
    tracked = ~table.empty
    if table.empty.any():
        notes.append(
            f"{where}: {int(table.empty.sum())} of {total} frames dropped: rigid body "
            f"{body!r} not tracked."
        )
    values, lines = table.values[tracked], table.lines[tracked]
    relative_ns = stamps_from_values(
        values[:, 0], ns_per_unit=float(_NS_PER_S), lines=lines, where=where, unit="s"
    )
    start_ns, start_note = _capture_start_ns(layout.meta, where=where)
    notes.append(start_note)
    positions = values[:, 1:4] * scale
    quat = values[:, 4:8] if rotation_cols else None
    options = {"up": up_axis} if up_axis is not None else {}
    trajectory = build_trajectory(
        relative_ns + np.int64(start_ns),
        positions,
        quat,
        where=where,
        line_numbers=lines,
        name=name,
        source=str(SourceSpec(TrajectoryFormat.MOTIVE, path, body, options)),
        frame_id=MOTIVE_FRAME_ID,
        child_frame_id=body,
        warnings=tuple(notes),
    )
    if up == "y":
        return trajectory.transformed(Y_UP_TO_Z_UP).with_warnings(
            f"{where}: converted Motive Y-up to REP 103 Z-up: (x, y, z) -> (x, -z, y), "
            "orientations rotated +90° about x."
        )
    return trajectory.with_warnings(f"{where}: axes already Z-up; not rotated.")


def _read_layout(text: str, *, where: str) -> _Layout:
    head: list[str] = []
    for raw in io.StringIO(text):
        head.append(raw.rstrip("\r\n"))
        if len(head) >= _HEADER_SEARCH_LINES:
            break
    rows = csv_rows(head, ",", where=where)
    first = [cell.strip() for cell in rows[0]] if rows else []
    if not first or first[0] != "Format Version":
        msg = (
            f"{where}, line 1: no 'Format Version' header, so not a Motive CSV export; "
            "export the take as CSV from Motive, or name another format with a prefix."
        )
        raise ReaderError(msg)
    meta = {first[i]: first[i + 1] for i in range(0, len(first) - 1, 2) if first[i]}
    frame_line = next((i for i, row in enumerate(rows) if row and row[0].strip() == "Frame"), None)
    if frame_line is None:
        msg = (
            f"{where}: no 'Frame,Time (Seconds),...' row in the first {_HEADER_SEARCH_LINES} "
            "lines; re-export the take as CSV with the header rows included."
        )
        raise ReaderError(msg)
    labels: dict[str, list[str]] = {}
    quantities: list[str] = []
    for row in rows[1:frame_line]:
        cells = [cell.strip() for cell in row]
        if not any(cells):
            continue
        label = cells[1] if len(cells) > 1 and not cells[0] else cells[0]
        if label in _LABELS:
            labels[label] = cells
        elif not cells[0] and len(cells) > 1 and any(c in _QUANTITIES for c in cells):
            quantities = cells
    axes = [cell.strip() for cell in rows[frame_line]]
    if "Type" not in labels or "Name" not in labels or not quantities:
        msg = (
            f"{where}: the header rows lack 'Type', 'Name' or the Rotation/Position row "
            f"(Format Version {meta.get('Format Version', '?')!r}); re-export the take as CSV "
            "from Motive 2 or 3 with the header rows included."
        )
        raise ReaderError(msg)
    return _Layout(meta, labels, quantities, axes, frame_line)


def _cell(row: list[str], j: int) -> str:
    return row[j] if j < len(row) else ""


def _rigid_bodies(layout: _Layout) -> list[str]:
    types, names = layout.labels["Type"], layout.labels["Name"]
    bodies: list[str] = []
    for j, kind in enumerate(types):
        body = _cell(names, j)
        if kind == "Rigid Body" and body and body not in bodies:
            bodies.append(body)
    return bodies


def _pick_body(bodies: list[str], wanted: str | None, *, path: Path) -> str:
    where = str(path)
    if not bodies:
        msg = f"{where}: no Rigid Body columns; export the take with rigid bodies included."
        raise ReaderError(msg)
    listed = ", ".join(repr(b) for b in bodies)
    if wanted is None:
        if len(bodies) == 1:
            return bodies[0]
        msg = (
            f"{where} holds {len(bodies)} rigid bodies ({listed}); pick one with "
            f"motive:{path}@NAME."
        )
        raise ReaderError(msg)
    if wanted not in bodies:
        msg = (
            f"{where}: no rigid body {wanted!r}; the export holds {listed}, pick one with "
            f"motive:{path}@NAME."
        )
        raise ReaderError(msg)
    return wanted


def _body_columns(layout: _Layout, body: str, *, where: str) -> tuple[int, list[int], list[int]]:
    """Return (time column, position X Y Z columns, rotation X Y Z W columns or [])."""
    time_col = next(
        (j for j, cell in enumerate(layout.axes) if cell.lower().startswith("time")), None
    )
    if time_col is None:
        msg = (
            f"{where}, line {layout.frame_line + 1}: no 'Time (Seconds)' column; re-export "
            "the take with the time column."
        )
        raise ReaderError(msg)
    types, names = layout.labels["Type"], layout.labels["Name"]
    found: dict[tuple[str, str], int] = {}
    for j, kind in enumerate(types):
        if kind == "Rigid Body" and _cell(names, j) == body:
            found.setdefault((_cell(layout.quantities, j), _cell(layout.axes, j).upper()), j)
    position = [found.get(("Position", axis)) for axis in "XYZ"]
    if any(j is None for j in position):
        msg = (
            f"{where}: rigid body {body!r} has no Position X, Y and Z columns; export the take "
            "with rigid body positions."
        )
        raise ReaderError(msg)
    rotation_type = layout.meta.get("Rotation Type", "Quaternion").strip()
    rotation = [found.get(("Rotation", axis)) for axis in "XYZW"]
    has_rotation = any(j is not None for j in rotation)
    if has_rotation and (rotation_type.lower() != "quaternion" or any(j is None for j in rotation)):
        msg = (
            f"{where}: rigid body {body!r} has rotations as {rotation_type!r} (Euler angles), "
            "not quaternions; re-export the take with Rotation Type Quaternion."
        )
        raise ReaderError(msg)
    return (
        time_col,
        [j for j in position if j is not None],
        [j for j in rotation if j is not None],
    )


def _up_axis(meta: Mapping[str, str], given: str | None, *, where: str) -> str:
    raw = given if given is not None else meta.get("Up Axis", "Y")
    axis = raw.strip().lower().removesuffix("axis").removesuffix("-up").strip()
    if axis not in {"y", "z"}:
        msg = f"{where}: up axis {raw!r} is not Y or Z; give up=y or up=z."
        raise ReaderError(msg)
    return axis


def _length_scale(meta: Mapping[str, str], *, where: str) -> float | None:
    raw = meta.get("Length Units")
    if raw is None:
        return None
    scale = _LENGTH_UNITS.get(raw.strip().lower())
    if scale is None:
        msg = (
            f"{where}: Length Units {raw!r} is not Meters, Centimeters or Millimeters; "
            "re-export the take in one of those."
        )
        raise ReaderError(msg)
    return scale


def _capture_start_ns(meta: Mapping[str, str], *, where: str) -> tuple[int, str]:
    """Return (start of the take in epoch nanoseconds or 0, the warning to record)."""
    raw = meta.get("Capture Start Time", "").strip()
    for fmt in _START_TIME_FORMATS:
        try:
            start = datetime.strptime(raw, fmt)  # noqa: DTZ007  (Motive stores no zone)
        except ValueError:
            continue
        seconds = calendar.timegm(start.timetuple())
        note = (
            f"{where}: Capture Start Time {raw!r} has no time zone and was read as UTC; "
            "shift the stamps by the site's UTC offset if the other source uses epoch time."
        )
        return seconds * _NS_PER_S + start.microsecond * 1000, note
    note = (
        f"{where}: no readable Capture Start Time ({raw!r}); stamps are seconds since the "
        "start of the take."
    )
    return 0, note
