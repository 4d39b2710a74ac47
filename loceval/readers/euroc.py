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
    ``timestamp, x, y, z`` or ``timestamp, x, y`` rows are accepted.

    Args:
        path: the file.
        name: the trajectory's name.

    Returns:
        The trajectory; ``source`` is ``euroc:PATH``.

    Raises:
        ReaderError: the file is missing or unreadable, a row is too short or holds a
            non-number, a value is NaN/inf, a quaternion is not unit, or fewer than three
            poses remain.
    """
    path = Path(path)
    where = str(path)
    text = load_text(path)
    skip, first = _skip_header_row(text)
    width = first.count(",") + 1 if first else 0
    if first and width not in {3, 4} and width < 8:
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
