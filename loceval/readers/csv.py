"""Reader for generic CSV trajectories: a header row and a column mapping.

The delimiter (comma, semicolon, tab, else whitespace) is sniffed from the header row. The
header is the row just above the first row of numbers; a leading ``#`` on it is dropped and
rows above it are ignored. Columns are found by name (case-insensitive; a unit in brackets
such as ``x [m]`` or ``time (s)`` is read and dropped):

=====  ========================================================================
key    recognised names (first match wins)
=====  ========================================================================
t      t, time, timestamp, stamp, sec, seconds, ``header.stamp``, ``%time``, and
       ``t_ns``, ``time_ms``, ``stamp_us``, ``timestamp_s`` ... (the suffix is the unit)
x y z  x, px, pos_x, position_x, p_x, tx, ``*position.x``, ``*translation.x``
qx...  qx, q_x, quat_x, orientation_x, ``*orientation.x``, ``*rotation.x`` (same for
       qy, qz, qw)
=====  ========================================================================

``t``, ``x`` and ``y`` are required; ``z`` defaults to 0 and the quaternion is all four
columns or none (position-only). An explicit mapping (``columns={"t": "Time"}``, or
``csv:FILE@t=Time,x=PosX``) overrides the names per key.

The time unit comes from ``time_unit``, else the column name (``_ns``, ``[ms]``,
``(seconds)``; ROS ``%time`` and ``header.stamp`` are nanoseconds), else seconds. Integer
stamps in ns, us or ms are read exactly. Lengths are metres unless ``length_unit`` or the
position columns' bracketed unit (m, cm, mm) say otherwise. Rows with an empty cell in a
used column are dropped and counted in a warning.
"""

from __future__ import annotations

import io
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np

from loceval.core.arrays import IntArray, StampsNs
from loceval.errors import ReaderError
from loceval.readers._common import build_trajectory
from loceval.readers.source import SourceSpec, TrajectoryFormat
from loceval.readers.text import csv_rows, load_text, parse_table, stamps_from_values
from loceval.trajectory import Trajectory

__all__ = ["CSV_KEYS", "LENGTH_UNITS", "TIME_UNITS", "read_csv"]

CSV_KEYS: Final = ("t", "x", "y", "z", "qx", "qy", "qz", "qw")
"""The keys a column mapping may name."""

TIME_UNITS: Final[Mapping[str, int]] = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
"""Time units and their nanoseconds."""

LENGTH_UNITS: Final[Mapping[str, float]] = {"m": 1.0, "cm": 0.01, "mm": 0.001}
"""Length units and their metres."""

_UNIT_SPELLINGS: Final[Mapping[str, str]] = {
    **dict.fromkeys(("s", "sec", "secs", "second", "seconds"), "s"),
    **dict.fromkeys(("ms", "msec", "millisecond", "milliseconds"), "ms"),
    **dict.fromkeys(("us", "µs", "usec", "microsecond", "microseconds"), "us"),
    **dict.fromkeys(("ns", "nsec", "nanosecond", "nanoseconds"), "ns"),
    **dict.fromkeys(("m", "meter", "meters", "metre", "metres"), "m"),
    **dict.fromkeys(("cm", "centimeter", "centimeters", "centimetre", "centimetres"), "cm"),
    **dict.fromkeys(("mm", "millimeter", "millimeters", "millimetre", "millimetres"), "mm"),
}
_TIME_NAMES: Final = ("t", "time", "timestamp", "stamp", "times", "sec", "secs", "seconds")
_ROS_TIME_NAMES: Final = ("header.stamp", "field.header.stamp", "%time")
_AXIS_NAMES: Final = ("{}", "p{}", "pos_{}", "position_{}", "p_{}", "t{}", "t_{}", "p_rs_r_{}")
_QUAT_NAMES: Final = ("q{}", "q_{}", "quat_{}", "orientation_{}", "quaternion_{}", "q_rs_{}")
_AXIS_SUFFIXES: Final = ("position.{}", "translation.{}")
_QUAT_SUFFIXES: Final = ("orientation.{}", "rotation.{}")
_UNIT_RE: Final = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\])]*)[\])]$")
_DELIMITERS: Final = (",", ";", "\t")
_MAX_PLAUSIBLE_SECONDS: Final = 1e11  # year 5138: larger "seconds" are surely another unit


@dataclass(frozen=True, slots=True)
class _Column:
    index: int
    header: str  # as written, for messages
    name: str  # normalized
    unit: str | None  # normalized unit from brackets or a name suffix


def read_csv(
    path: Path,
    *,
    columns: Mapping[str, str] | None = None,
    time_unit: str | None = None,
    length_unit: str | None = None,
    name: str = "",
) -> Trajectory:
    """Read a CSV with a header row through a column mapping (see the module docstring).

    Args:
        path: the file.
        columns: header names per key (``t``, ``x`` ... ``qw``); unmapped keys use the
            recognised names.
        time_unit: ``s``, ``ms``, ``us`` or ``ns``; None to take it from the name.
        length_unit: ``m``, ``cm`` or ``mm``; None to take it from the header (else m).
        name: the trajectory's name.

    Returns:
        The trajectory; ``source`` is ``csv:PATH`` plus the options given.

    Raises:
        ReaderError: the file is missing or unreadable, has no header row, a column is
            missing or mapped to an unknown header, a cell is not a number, a value is
            NaN/inf, a quaternion is not unit, or fewer than three poses remain.
    """
    path = Path(path)
    where = str(path)
    text = load_text(path)
    header_index, delimiter, headers = _find_header(text, where=where)
    table_columns = [_column(i, h) for i, h in enumerate(headers)]
    mapping = dict(columns or {})
    chosen = _choose_columns(table_columns, mapping, where=where, header_line=header_index + 1)
    t_unit, t_unit_given = _time_unit(chosen["t"], time_unit, where=where)
    used = [key for key in CSV_KEYS if key in chosen]
    table = parse_table(
        text,
        where=where,
        delimiter=delimiter,
        hint="every row needs a cell for each mapped column",
        skip_lines=header_index + 1,
        usecols=[chosen[key].index for key in used],
        names=[chosen[key].header for key in used],
        empty_cells=True,
        int_first=t_unit != "s",
    )
    notes: list[str] = []
    keep = ~table.empty
    if table.empty.any():
        first = int(table.lines[np.flatnonzero(table.empty)[0]])
        notes.append(
            f"{where}: {int(table.empty.sum())} of {len(table)} rows dropped because a used "
            f"cell was empty (first at line {first})."
        )
    values, lines = table.values[keep], table.lines[keep]
    ns_per_unit = TIME_UNITS[t_unit]
    if table.first_int is not None:
        stamps = _exact_stamps(table.first_int[keep], ns_per_unit, lines, where=where)
    else:
        stamps_raw = values[:, 0]
        finite = np.abs(stamps_raw[np.isfinite(stamps_raw)])
        if not t_unit_given and finite.size and finite.max() > _MAX_PLAUSIBLE_SECONDS:
            msg = (
                f"{where}, column {chosen['t'].header!r}: stamps up to {float(finite.max()):.6g} "
                f"are too large for seconds; name the unit, e.g. csv:{path}@time_unit=ns."
            )
            raise ReaderError(msg)
        stamps = stamps_from_values(
            stamps_raw, ns_per_unit=float(ns_per_unit), lines=lines, where=where, unit=t_unit
        )
    column_of = {key: j for j, key in enumerate(used)}
    positions = np.zeros((len(values), 3))
    for axis, key in enumerate(("x", "y", "z")):
        if key in column_of:
            scale = _length_scale(chosen[key], length_unit, where=where)
            positions[:, axis] = values[:, column_of[key]] * scale
    quat = None
    if "qw" in column_of:
        quat = values[:, [column_of[k] for k in ("qx", "qy", "qz", "qw")]]
    options = dict(mapping)
    if time_unit is not None:
        options["time_unit"] = time_unit
    if length_unit is not None:
        options["length_unit"] = length_unit
    return build_trajectory(
        stamps,
        positions,
        quat,
        where=where,
        line_numbers=lines,
        name=name,
        source=str(SourceSpec(TrajectoryFormat.CSV, path, None, options)),
        warnings=tuple(notes),
    )


def _exact_stamps(ints: StampsNs, ns_per_unit: int, lines: IntArray, *, where: str) -> StampsNs:
    """Scale exact integer stamps to nanoseconds, refusing what int64 cannot hold."""
    limit = np.iinfo(np.int64).max // ns_per_unit
    bad = np.flatnonzero(np.abs(ints) > limit)
    if bad.size:
        i = int(bad[0])
        msg = (
            f"{where}, line {int(lines[i])}: stamp {int(ints[i])} is too large for its unit; "
            "check the time unit."
        )
        raise ReaderError(msg)
    out: StampsNs = ints * np.int64(ns_per_unit)
    return out


def _find_header(text: str, *, where: str) -> tuple[int, str | None, list[str]]:
    """Return (0-based header line, delimiter, header cells)."""
    previous: tuple[int, str] | None = None
    for index, raw in enumerate(io.StringIO(text)):
        line = raw.strip()
        if not line:
            continue
        if _looks_numeric(line):
            if previous is None:
                msg = (
                    f"{where}, line {index + 1}: numbers but no header row above them; add a "
                    "header naming the columns, e.g. t,x,y,z,qx,qy,qz,qw."
                )
                raise ReaderError(msg)
            header_index, header = previous
            delimiter = max(_DELIMITERS, key=header.count)
            sep = delimiter if header.count(delimiter) else None
            cells = _header_cells(header.lstrip("#"), sep, where=where)
            return header_index, sep, [cell.strip() for cell in cells]
        previous = (index, line)
    msg = (
        f"{where}: no rows of numbers under a header; check that this is a trajectory CSV "
        "with a header such as t,x,y,z,qx,qy,qz,qw."
    )
    raise ReaderError(msg)


def _header_cells(line: str, delimiter: str | None, *, where: str) -> list[str]:
    if delimiter is None:
        return line.split()
    return csv_rows([line], delimiter, where=where)[0]


def _looks_numeric(line: str) -> bool:
    first = re.split(r"[,;\s]", line.strip(), maxsplit=1)[0]
    try:
        float(first)
    except ValueError:
        return False
    return True


def _column(index: int, header: str) -> _Column:
    text = header.strip().strip('"').strip().lstrip("#").strip()
    name, unit = text.lower(), None
    match = _UNIT_RE.match(name)
    if match:
        name, unit = match["name"].strip(), match["unit"].strip()
    name = re.sub(r"[\s\-]+", "_", name)
    if unit is None:
        base, sep, suffix = name.rpartition("_")
        if sep and suffix in _UNIT_SPELLINGS and base:
            name, unit = base, suffix
    return _Column(index, header, name, _UNIT_SPELLINGS.get(unit, unit) if unit else None)


def _alias_rank(key: str, column: _Column) -> int | None:
    """Return how well a column's name matches a key (lower is better), or None."""
    name = column.name
    if key == "t":
        candidates = [*_TIME_NAMES, *_ROS_TIME_NAMES]
        return candidates.index(name) if name in candidates else None
    if key in {"x", "y", "z"}:
        exact = [pattern.format(key) for pattern in _AXIS_NAMES]
        suffixes = [pattern.format(key) for pattern in _AXIS_SUFFIXES]
    else:
        exact = [pattern.format(key[1]) for pattern in _QUAT_NAMES]
        suffixes = [pattern.format(key[1]) for pattern in _QUAT_SUFFIXES]
    if name in exact:
        return exact.index(name)
    for rank, suffix in enumerate(suffixes):
        if name.endswith(suffix):
            return len(exact) + rank
    return None


def _choose_columns(
    columns: list[_Column], mapping: dict[str, str], *, where: str, header_line: int
) -> dict[str, _Column]:
    headers = [c.header for c in columns]
    unknown = sorted(set(mapping) - set(CSV_KEYS))
    if unknown:
        msg = (
            f"{where}: unknown column key {unknown[0]!r}; map the keys "
            f"{', '.join(CSV_KEYS)} to header names, e.g. t=time,x=px."
        )
        raise ReaderError(msg)
    chosen: dict[str, _Column] = {}
    for key in CSV_KEYS:
        if key in mapping:
            wanted = mapping[key].strip()
            found = [c for c in columns if c.header == wanted] or [
                c for c in columns if c.header.lower() == wanted.lower()
            ]
            if not found:
                msg = (
                    f"{where}, line {header_line}: no column {wanted!r} for {key!r}; map {key} "
                    f"to one of the header's columns {headers!r}."
                )
                raise ReaderError(msg)
            chosen[key] = found[0]
            continue
        ranked = [(rank, c.index, c) for c in columns if (rank := _alias_rank(key, c)) is not None]
        if ranked:
            chosen[key] = min(ranked, key=lambda item: (item[0], item[1]))[2]
    for key in ("t", "x", "y"):
        if key not in chosen:
            msg = (
                f"{where}, line {header_line}: no column for {key!r} among {headers!r}; map it, "
                f"e.g. csv:{where}@{key}=COLUMN (keys {', '.join(CSV_KEYS)})."
            )
            raise ReaderError(msg)
    quat = [key for key in ("qx", "qy", "qz", "qw") if key in chosen]
    if quat and len(quat) != 4:
        missing = [key for key in ("qx", "qy", "qz", "qw") if key not in chosen]
        msg = (
            f"{where}, line {header_line}: quaternion columns {quat!r} found but not "
            f"{missing!r} among {headers!r}; map all four (e.g. csv:{where}@qw=COLUMN) or none."
        )
        raise ReaderError(msg)
    return chosen


def _time_unit(column: _Column, given: str | None, *, where: str) -> tuple[str, bool]:
    """Return (unit, whether it was stated) for the time column."""
    if given is not None:
        unit = _UNIT_SPELLINGS.get(given.strip().lower(), "")
        if unit not in TIME_UNITS:
            msg = f"{where}: unknown time unit {given!r}; use one of {', '.join(TIME_UNITS)}."
            raise ReaderError(msg)
        return unit, True
    if column.unit is not None:
        if column.unit not in TIME_UNITS:
            msg = (
                f"{where}: unknown time unit {column.unit!r} in column {column.header!r}; name "
                f"it with time_unit= (one of {', '.join(TIME_UNITS)})."
            )
            raise ReaderError(msg)
        return column.unit, True
    if column.name in _ROS_TIME_NAMES:
        return "ns", True
    return "s", False


def _length_scale(column: _Column, given: str | None, *, where: str) -> float:
    unit = given.strip().lower() if given is not None else column.unit
    if unit is None:
        return 1.0
    canonical = _UNIT_SPELLINGS.get(unit, unit)
    if canonical not in LENGTH_UNITS:
        msg = (
            f"{where}: unknown length unit {unit!r} for column {column.header!r}; use "
            f"length_unit= with one of {', '.join(LENGTH_UNITS)}."
        )
        raise ReaderError(msg)
    return LENGTH_UNITS[canonical]
