"""Readers of the small tables a survey gives: control points and visit windows.

Control points (``points:survey.csv``): a header ``id,x,y,z`` and optionally ``sigma_m``
(one sigma for every axis) or ``sigma_xy_m,sigma_z_m``, metres in the building frame.
Visits (``--visits FILE``): a header ``id,t_start,t_end``, seconds on the estimate's clock,
one row per visit; a point may be visited several times.

Cells are separated by commas, semicolons or tabs; ``#`` starts a comment line; column
names are matched without regard to case, spaces or a unit suffix in brackets.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from loceval.controlpoints import ControlPoints, Visits
from loceval.core.arrays import FloatArray
from loceval.errors import InputError, ReaderError
from loceval.readers._common import seconds_to_ns
from loceval.readers.text import SURVEY_DELIMITERS, load_text, split_line
from loceval.trajectory import MAX_COORDINATE_M, MAX_SPAN_S

__all__ = [
    "looks_like_control_points",
    "looks_like_visits",
    "read_control_points",
    "read_visit_table",
    "read_visits",
]

_UNIT = re.compile(r"\s*[\[(].*[\])]\s*$")
_POINT_KEYS = ("id", "x", "y", "z")
_VISIT_KEYS = ("id", "t_start", "t_end")
_ALIASES = {
    "id": ("id", "point", "point_id", "name", "label"),
    "sigma_m": ("sigma_m", "sigma"),
    "sigma_xy_m": ("sigma_xy_m", "sigma_xy", "sigma_h_m"),
    "sigma_z_m": ("sigma_z_m", "sigma_z", "sigma_v_m"),
    "t_start": ("t_start", "t_start_s", "start", "start_s"),
    "t_end": ("t_end", "t_end_s", "end", "end_s"),
}


def _normalise(cell: str) -> str:
    return _UNIT.sub("", cell).strip().lower().replace(" ", "_").replace("-", "_")


def _header_keys(cells: list[str]) -> dict[str, int]:
    """Map every recognised key to its column; the first of several aliases wins."""
    names = [_normalise(c) for c in cells]
    found: dict[str, int] = {}
    for key in (*_POINT_KEYS, *_ALIASES):
        for alias in _ALIASES.get(key, (key,)):
            if alias in names and key not in found:
                found[key] = names.index(alias)
    return found


def _first_row(text: str) -> list[str] | None:
    for line in text.splitlines():
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            return _split(stripped)
    return None


def _split(line: str, *, where: str = "The table") -> list[str]:
    """Split a row at its first delimiter among ``, ; TAB`` (CSV quoting), else whitespace.

    Raises:
        ReaderError: not CSV the csv module can split (a huge cell, a stray line break).
    """
    delimiter = next((d for d in SURVEY_DELIMITERS if d in line), None)
    return [cell.strip() for cell in split_line(line, delimiter, where=where)]


def looks_like_control_points(first_line: str) -> bool:
    """Tell whether a header row is a control-point survey (``id,x,y,z`` and no time)."""
    try:
        cells = _split(first_line.strip())
    except ReaderError:  # not CSV the csv module splits: no survey header
        return False
    keys = _header_keys(cells)
    timed = {"t", "time", "timestamp", "t_start"} & {_normalise(c) for c in cells}
    return all(k in keys for k in _POINT_KEYS) and not timed


def looks_like_visits(first_line: str) -> bool:
    """Tell whether a header row is a visits table (``id,t_start,t_end``)."""
    try:
        keys = _header_keys(_split(first_line.strip()))
    except ReaderError:  # not CSV the csv module splits: no visits header
        return False
    return all(k in keys for k in _VISIT_KEYS)


def _rows(
    path: Path, required: tuple[str, ...], what: str
) -> tuple[dict[str, int], list[tuple[int, list[str]]]]:
    where = str(path)
    text = load_text(path)
    lines = [(k + 1, line.strip()) for k, line in enumerate(text.splitlines())]
    lines = [(n, line) for n, line in lines if line and not line.startswith("#")]
    if not lines:
        msg = f"{where} is empty; {what} need a header row {','.join(required)} and rows."
        raise ReaderError(msg)
    header_line, header = lines[0]
    keys = _header_keys(_split(header, where=where))
    missing = [k for k in required if k not in keys]
    if missing:
        msg = (
            f"{where}, line {header_line}: the header {header[:120]!r} has no column "
            f"{', '.join(repr(m) for m in missing)}; {what} need a header "
            f"{','.join(required)}."
        )
        raise ReaderError(msg)
    rows = [(n, _split(line, where=where)) for n, line in lines[1:]]
    if not rows:
        msg = f"{where} has a header but no rows; add one row per {what[:-1]}."
        raise ReaderError(msg)
    width = max(keys.values()) + 1
    short = next(((n, r) for n, r in rows if len(r) < width), None)
    if short is not None:
        msg = (
            f"{where}, line {short[0]}: {len(short[1])} cells, the header needs {width}; "
            "every row needs a cell for each column."
        )
        raise ReaderError(msg)
    return keys, rows


def _numbers(
    rows: list[tuple[int, list[str]]], column: int, *, where: str, name: str
) -> FloatArray:
    out = np.empty(len(rows))
    for k, (line, cells) in enumerate(rows):  # survey tables hold tens to hundreds of rows
        try:
            out[k] = float(cells[column])
        except ValueError:
            msg = f"{where}, line {line}: {name} {cells[column]!r} is not a number."
            raise ReaderError(msg) from None
        if not np.isfinite(out[k]):
            msg = f"{where}, line {line}: {name} is {cells[column]!r}; give a finite number."
            raise ReaderError(msg)
    return out


def read_control_points(path: Path) -> ControlPoints:
    """Read a control-point survey (see the module docstring).

    Raises:
        ReaderError: the file cannot be read, lacks a column, has a non-number, a negative
            sigma, a coordinate beyond 1e9 m, duplicate ids or fewer than 3 points.
    """
    path = Path(path)
    where = str(path)
    keys, rows = _rows(path, _POINT_KEYS, "control points")
    ids = [cells[keys["id"]] for _, cells in rows]
    empty = next((line for (line, _), pid in zip(rows, ids, strict=True) if not pid), None)
    if empty is not None:
        msg = f"{where}, line {empty}: the point has no id; give every point an id."
        raise ReaderError(msg)
    xyz = np.stack([_numbers(rows, keys[a], where=where, name=a) for a in "xyz"], axis=1)
    if (np.abs(xyz) > MAX_COORDINATE_M).any():
        msg = f"{where}: coordinates beyond {MAX_COORDINATE_M:g} m; give metres."
        raise ReaderError(msg)
    sigma = None
    if "sigma_m" in keys:
        s = _numbers(rows, keys["sigma_m"], where=where, name="sigma_m")
        sigma = np.repeat(s[:, None], 3, axis=1)
    elif "sigma_xy_m" in keys and "sigma_z_m" in keys:
        h = _numbers(rows, keys["sigma_xy_m"], where=where, name="sigma_xy_m")
        v = _numbers(rows, keys["sigma_z_m"], where=where, name="sigma_z_m")
        sigma = np.stack([h, h, v], axis=1)
    elif "sigma_xy_m" in keys or "sigma_z_m" in keys:
        msg = f"{where}: give both sigma_xy_m and sigma_z_m, or one sigma_m for every axis."
        raise ReaderError(msg)
    if sigma is not None and (sigma < 0).any():
        line = rows[int(np.flatnonzero((sigma < 0).any(axis=1))[0])][0]
        msg = f"{where}, line {line}: a sigma is negative; give the survey's 1-sigma in metres."
        raise ReaderError(msg)
    try:
        return ControlPoints(tuple(ids), xyz, sigma, source=f"points:{path.name}")
    except InputError as err:  # duplicate ids, too few points: name the file
        msg = f"{where}: {err}"
        raise ReaderError(msg) from err


def read_visits(path: Path, points: ControlPoints) -> Visits:
    """Read a visits table (see the module docstring) against the control points.

    Raises:
        ReaderError: the file cannot be read, lacks a column, has a non-number, names a
            point that is not surveyed, or a visit ends before it starts.
    """
    ids, start, end = read_visit_table(path)
    try:
        index = points.index_of(list(ids), where=str(path))
    except InputError as err:
        raise ReaderError(str(err)) from err
    return Visits(index, seconds_to_ns(start), seconds_to_ns(end), source="file")


def read_visit_table(path: Path) -> tuple[tuple[str, ...], FloatArray, FloatArray]:
    """Read a visits table's rows without the survey: ids, start and end seconds.

    Raises:
        ReaderError: the file cannot be read, lacks a column, has a non-number, or a
            visit ends before it starts.
    """
    path = Path(path)
    where = str(path)
    keys, rows = _rows(path, _VISIT_KEYS, "visits")
    ids = [cells[keys["id"]] for _, cells in rows]
    start = _numbers(rows, keys["t_start"], where=where, name="t_start")
    end = _numbers(rows, keys["t_end"], where=where, name="t_end")
    if (np.abs(np.concatenate([start, end])) > MAX_SPAN_S * 10).any():
        msg = f"{where}: visit times must be seconds (like the estimate's stamps)."
        raise ReaderError(msg)
    backwards = np.flatnonzero(end < start)
    if backwards.size:
        line = rows[int(backwards[0])][0]
        msg = f"{where}, line {line}: the visit ends before it starts; give t_start <= t_end."
        raise ReaderError(msg)
    return tuple(ids), start, end
