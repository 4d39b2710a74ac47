"""The EuRoC MAV CSV format: ``timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z, ...``."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Final

import numpy as np

from loceval.errors import ReaderError
from loceval.readers._common import build_trajectory
from loceval.readers.source import SourceSpec, TrajectoryFormat
from loceval.readers.text import load_text, parse_table, positions_and_quat, stamps_from_values
from loceval.trajectory import Trajectory

__all__ = ["read_euroc"]

_EUROC_NAMES: Final = ("timestamp", "p_x", "p_y", "p_z", "q_w", "q_x", "q_y", "q_z")
_SECONDS_LIKE_NS: Final = 1e11
"""Fractional EuRoC stamps below this (100 s after 1970) are seconds, not nanoseconds."""


def read_euroc(path: Path, *, name: str = "") -> Trajectory:
    """Read a EuRoC ground-truth or estimate CSV.

    Columns are ``timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z`` followed by any
    number of ignored columns (velocities, biases); the quaternion is w-first in the file
    and x y z w in the result. Stamps are parsed exactly as int64 nanoseconds. A ``#``
    header (or one header row without ``#``) is skipped. Position-only files with
    ``timestamp, x, y, z`` or ``timestamp, x, y`` rows are accepted, but a file whose
    header names EuRoC's ground-truth columns (``p_RS_R_x`` ...) without their orientation
    (``q_RS_w`` ...) is refused: that is a ground-truth export that lost its quaternion,
    and the message says to read it with the ``csv:`` prefix if position-only is meant.

    Args:
        path: the file.
        name: the trajectory's name.

    Returns:
        The trajectory; ``source`` is ``euroc:PATH``.

    Raises:
        ReaderError: the file is missing or unreadable, holds no data rows, has a EuRoC
            header without the orientation columns, a row is too short or holds a
            non-number, a value is NaN/inf, a quaternion is not unit, or fewer than three
            poses remain.
    """
    path = Path(path)
    where = str(path)
    text = load_text(path)
    skip, first = _skip_header_row(text)
    _check_rows_and_columns(text, first, where=where)
    width = first.count(",") + 1
    if width not in {3, 4} and width < 8:
        msg = (
            f"{where}, line {skip + 1}: {width} columns, but a EuRoC row holds "
            "timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z (8 or more) or timestamp, x, y[, z]; "
            "check the file or name its format with a prefix."
        )
        raise ReaderError(msg)
    used = min(8, width)
    hint = "a EuRoC row holds timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z"
    table = parse_table(
        text,
        where=where,
        delimiter=",",
        hint=hint,
        skip_lines=skip,
        usecols=range(used),
        names=_EUROC_NAMES[:used],
        comments="#",
        int_first=True,
    )
    notes: list[str] = []
    if table.first_int is not None:
        stamps = table.first_int
    else:
        first_stamps = table.values[:, 0]
        if (
            len(table)
            and float(np.abs(first_stamps).max()) < _SECONDS_LIKE_NS
            and bool((first_stamps != np.round(first_stamps)).any())
        ):
            msg = (
                f"{where}, line {int(table.lines[0])}: EuRoC stamps are integer nanoseconds, "
                f"but {float(table.values[0, 0])!r} looks like seconds; multiply the first "
                "column by 1e9, or read the file as tum:FILE after swapping to x y z qx qy "
                "qz qw order."
            )
            raise ReaderError(msg)
        stamps = stamps_from_values(
            table.values[:, 0] if len(table) else np.zeros(0),
            ns_per_unit=1.0,
            lines=table.lines,
            where=where,
            unit="ns",
        )
        if len(table):
            notes.append(
                f"{where}: stamps are not integer nanoseconds; they were rounded to the "
                "nearest nanosecond."
            )
    positions, quat_wxyz = positions_and_quat(table.values, used, quat_cols=[4, 5, 6, 7])
    quat = None if quat_wxyz is None else quat_wxyz[:, [1, 2, 3, 0]]
    return build_trajectory(
        stamps,
        positions,
        quat,
        where=where,
        line_numbers=table.lines,
        name=name,
        source=str(SourceSpec(TrajectoryFormat.EUROC, path)),
        warnings=tuple(notes),
    )


def _check_rows_and_columns(text: str, first: str, *, where: str) -> None:
    """Refuse a file without data rows, or a EuRoC header without its orientation columns."""
    header = _header_line(text)
    if not first:
        what = f"its header {header!r} but no data rows" if header else "no data rows"
        msg = (
            f"{where} holds {what}; a EuRoC file needs one row per pose (timestamp [ns], "
            "p_x, p_y, p_z, q_w, q_x, q_y, q_z): export the recording again."
        )
        raise ReaderError(msg)
    if header is None or first.count(",") + 1 >= 8:
        return
    header_cells = [cell.strip() for cell in header.lstrip("#").split(",")]
    width = first.count(",") + 1
    if len(header_cells) > width:
        # The header promises columns the rows do not carry: reading the rows as they are
        # would silently drop what the header says is there (the orientation, usually).
        missing = ", ".join(header_cells[width:])
        msg = (
            f"{where}: the rows do not match the header: the header names "
            f"{len(header_cells)} columns ({', '.join(header_cells)}) but the first row "
            f"holds {width} values ({first!r}); missing: {missing}. Export the file again "
            "with every column, or, if it holds positions only, let the header name only "
            "those (timestamp, x, y, z)."
        )
        raise ReaderError(msg)
    names = [cell.lower() for cell in header_cells]
    if not any("p_rs_r_" in name for name in names) or any(n.startswith("q") for n in names):
        # A header of its own (timestamp,x,y,z) says position-only on purpose; one with
        # quaternion columns leaves it to the rows' width (too few cells).
        return
    cells = ", ".join(cell.strip() for cell in header.lstrip("#").split(","))
    msg = (
        f"{where}: the header names the columns {cells} but no orientation columns "
        "(q_RS_w, q_RS_x, q_RS_y, q_RS_z), so these are positions only; export the "
        "ground truth with its quaternion, or read the file as position-only with the "
        f"csv: prefix (csv:{where})."
    )
    raise ReaderError(msg)


def _header_line(text: str) -> str | None:
    """Return the header row (``#``-prefixed or not) above the first data row, if any."""
    header = None
    for raw in io.StringIO(text):
        line = raw.strip()
        if not line:
            continue
        try:
            float(line.lstrip("#").split(",", 1)[0].strip())
        except ValueError:
            if "," in line:
                header = line
            continue
        if not line.startswith("#"):
            return header
    return header


def _skip_header_row(text: str) -> tuple[int, str]:
    """Return (lines to skip, first data line) for a CSV whose first row may be a header."""
    for index, raw in enumerate(io.StringIO(text)):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        first_cell = line.split(",", 1)[0].strip()
        try:
            float(first_cell)
        except ValueError:
            return index + 1, _next_data_line(text, index + 1)
        return 0, line
    return 0, ""


def _next_data_line(text: str, start: int) -> str:
    for index, raw in enumerate(io.StringIO(text)):
        line = raw.strip()
        if index >= start and line and not line.startswith("#"):
            return line
    return ""
