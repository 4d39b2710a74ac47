"""Readers for radio ranging systems (UWB, BLE, nanoPAN): anchor positions and ranges.

Two CSV files with a header row (delimiter comma, semicolon, tab, else whitespace; a
leading ``#`` on the header is dropped, blank lines and later ``#`` lines are skipped):

- **anchors**: ``id,x,y,z``, one fixed anchor per row, metres in the building frame.
  Anchor ids are text (``A1``, ``17``) and must be unique.
- **ranges**: ``t,anchor_id,range_m[,rssi]``, one measurement per row, ``t`` in seconds
  (or the unit the column name gives: ``t_ns``, ``time [ms]``). ``anchor_id`` is matched
  to the anchors' ids as written (``"1"`` is not ``"1.0"``).

Rows of the ranges file that cannot be used (a time or range that is not a finite
number, a negative range, an anchor id not in the anchors file, a wrong number of cells)
are dropped, counted per reason and named in one warning; a file with no usable row is
an error. Ranges from ROS bags (``sensor_msgs/msg/Range``) are read by
:func:`loceval.readers.rosbag.read_range_topic`. :func:`sniff_radio_table` tells the two
tables apart by their header (uploads are recognised by it).
"""

from __future__ import annotations

import io
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray, StampsNs
from loceval.errors import InputError, ReaderError
from loceval.readers.csv import TIME_UNITS
from loceval.readers.text import SURVEY_DELIMITERS, csv_rows, load_text, split_line
from loceval.trajectory import MAX_COORDINATE_M

__all__ = [
    "MIN_ANCHORS",
    "Anchors",
    "Ranges",
    "RangesOverview",
    "read_anchors",
    "read_ranges",
    "read_ranges_overview",
    "sniff_radio_table",
]

MIN_ANCHORS: Final = 3
"""Fewest anchors an anchors file may hold: positioning in 2D needs three."""

_UNIT_RE: Final = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\])]*)[\])]$")
_ANCHOR_NAMES: Final = {
    "id": ("id", "anchor", "anchor_id", "name"),
    "x": ("x", "x_m"),
    "y": ("y", "y_m"),
    "z": ("z", "z_m"),
}
_RANGE_NAMES: Final = {
    "t": ("t", "time", "timestamp", "stamp", "sec", "seconds"),
    "anchor_id": ("anchor_id", "anchor", "id", "anchorid"),
    "range_m": ("range_m", "range", "distance", "distance_m", "dist", "dist_m"),
    "rssi": ("rssi", "rssi_dbm"),
}
_UNIT_SPELLINGS: Final = {
    **dict.fromkeys(("s", "sec", "secs", "second", "seconds"), "s"),
    **dict.fromkeys(("ms", "msec", "millisecond", "milliseconds"), "ms"),
    **dict.fromkeys(("us", "µs", "usec", "microsecond", "microseconds"), "us"),
    **dict.fromkeys(("ns", "nsec", "nanosecond", "nanoseconds"), "ns"),
}
_DECIMAL_RE: Final = re.compile(r"(?P<sign>[-+]?)(?P<whole>\d*)(?:\.(?P<frac>\d*))?")
_NAMED_IDS: Final = 3  # unknown anchor ids quoted in the warning
_SNIFF_BYTES: Final = 65536


@dataclass(frozen=True, slots=True, eq=False)
class Anchors:
    """Fixed radio anchors in the building frame.

    Attributes:
        ids: (K,) unique anchor ids, in file order.
        positions_xyz: (K, 3) float64 metres.
        source: the file they came from.
    """

    ids: tuple[str, ...]
    positions_xyz: FloatArray
    source: str = ""

    def __post_init__(self) -> None:
        """Copy the positions, make them read-only and check ids, shape and values."""
        ids = tuple(str(i) for i in self.ids)
        positions = np.array(self.positions_xyz, dtype=np.float64, copy=True)
        k = len(ids)
        if positions.shape != (k, 3):
            msg = f"Anchor positions must have shape ({k}, 3), got {positions.shape!r}."
            raise InputError(msg)
        if not np.isfinite(positions).all() or (
            k and float(np.abs(positions).max()) > MAX_COORDINATE_M
        ):
            msg = "Anchor positions must be finite metres; check the anchors file."
            raise InputError(msg)
        if len(set(ids)) != k:
            dup = next(i for n, i in enumerate(ids) if i in ids[:n])
            msg = f"Anchor id {dup!r} appears twice; give every anchor its own id."
            raise InputError(msg)
        if k < MIN_ANCHORS:
            msg = (
                f"{k} anchors given, but positioning needs at least {MIN_ANCHORS}; "
                "list every anchor of the installation."
            )
            raise InputError(msg)
        positions.flags.writeable = False
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "positions_xyz", positions)

    def __len__(self) -> int:
        """Return the number of anchors."""
        return len(self.ids)


@dataclass(frozen=True, slots=True, eq=False)
class Ranges:
    """Range measurements from a tag to fixed anchors, sorted by time.

    Attributes:
        anchors: the anchors the measurements refer to.
        stamps_ns: (N,) int64 nanoseconds, non-decreasing (anchors may share a stamp).
        anchor_index: (N,) index of each measurement's anchor in ``anchors``.
        range_m: (N,) measured distances, finite and non-negative, metres.
        rssi: (N,) received signal strength (NaN where a row had none), or None.
        source: the file they came from.
        warnings: what the reader noticed (dropped rows per reason).
    """

    anchors: Anchors
    stamps_ns: StampsNs
    anchor_index: IntArray
    range_m: FloatArray
    rssi: FloatArray | None = None
    source: str = ""
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        """Copy the arrays, make them read-only and check shapes and values."""
        stamps = np.array(self.stamps_ns, copy=True)
        if stamps.ndim != 1 or not np.issubdtype(stamps.dtype, np.integer):
            msg = f"Range stamps must be a 1-D integer array of nanoseconds, got {stamps.dtype}."
            raise InputError(msg)
        n = stamps.shape[0]
        index = np.array(self.anchor_index, dtype=np.intp, copy=True)
        ranges = np.array(self.range_m, dtype=np.float64, copy=True)
        if index.shape != (n,) or ranges.shape != (n,):
            msg = (
                f"Ranges need one anchor index and one range per stamp ({n}), got shapes "
                f"{index.shape!r} and {ranges.shape!r}."
            )
            raise InputError(msg)
        if n and (index.min() < 0 or index.max() >= len(self.anchors)):
            msg = f"Anchor indices must lie in 0..{len(self.anchors) - 1}; check the ranges."
            raise InputError(msg)
        if not (np.isfinite(ranges) & (ranges >= 0)).all():
            msg = "Ranges must be finite and non-negative metres; the reader drops other rows."
            raise InputError(msg)
        if n > 1 and not (np.diff(stamps) >= 0).all():
            msg = "Range stamps must be sorted by time; the reader sorts them."
            raise InputError(msg)
        arrays: list[np.ndarray] = [stamps.astype(np.int64, copy=False), index, ranges]
        if self.rssi is not None:
            rssi = np.array(self.rssi, dtype=np.float64, copy=True)
            if rssi.shape != (n,):
                msg = f"RSSI must have shape ({n},), got {rssi.shape!r}."
                raise InputError(msg)
            arrays.append(rssi)
        for array in arrays:
            array.flags.writeable = False
        object.__setattr__(self, "stamps_ns", arrays[0])
        object.__setattr__(self, "anchor_index", arrays[1])
        object.__setattr__(self, "range_m", arrays[2])
        if self.rssi is not None:
            object.__setattr__(self, "rssi", arrays[3])
        object.__setattr__(self, "warnings", tuple(self.warnings))

    def __len__(self) -> int:
        """Return the number of measurements."""
        return int(self.stamps_ns.shape[0])


@dataclass(frozen=True, slots=True)
class RangesOverview:
    """What a ranges file holds, read without its anchors (an upload's inspection).

    Attributes:
        rows: data rows.
        anchor_ids: the distinct anchor ids, in order of first appearance.
    """

    rows: int
    anchor_ids: tuple[str, ...]


def sniff_radio_table(path: Path) -> str | None:
    """Tell a radio table by its header: ``"anchors"`` (``id,x,y,z``), ``"ranges"``.

    Returns:
        ``"ranges"`` for a header with a time, an anchor id and a range; ``"anchors"`` for
        one with an id and x, y, z but no time; None for anything else (or no file).
    """
    try:
        with Path(path).open("rb") as fh:
            head = fh.read(_SNIFF_BYTES).decode("utf-8", errors="replace")
    except OSError:
        return None
    for raw in head.splitlines():
        line = raw.strip()
        if not line or (line.startswith("#") and _is_comment(line)):
            continue
        try:
            cells = split_line(line.lstrip("#"), _delimiter_of(line))
        except ReaderError:  # not CSV the csv module splits: no radio table
            return None
        names = {_normalize(c)[0] for c in cells}
        names |= {n.rpartition("_")[0] for n in names if n.rpartition("_")[2] in _UNIT_SPELLINGS}
        if all(names & set(_RANGE_NAMES[k]) for k in ("t", "anchor_id", "range_m")):
            return "ranges"
        anchor_cols = all(names & set(_ANCHOR_NAMES[k]) for k in ("id", "x", "y", "z"))
        if anchor_cols and not names & set(_RANGE_NAMES["t"]):
            return "anchors"
        return None
    return None


def read_ranges_overview(path: Path) -> RangesOverview:
    """Count a ranges file's rows and list its anchor ids, without the anchors file.

    Raises:
        ReaderError: the file is missing or unreadable, has no header or lacks a column,
            or the time unit is unknown.
    """
    where = str(path)
    header_line, headers, rows, _ = _read_rows(load_text(Path(path)), where=where, kind="ranges")
    cols = _choose(
        headers, _RANGE_NAMES, ("t", "anchor_id", "range_m"), where=where, line=header_line
    )
    _time_scale(headers[cols["t"]], where=where)
    width = len(headers)
    ids = dict.fromkeys(r[cols["anchor_id"]].strip() for r in rows if len(r) == width)
    return RangesOverview(rows=len(rows), anchor_ids=tuple(ids))


def read_anchors(path: Path) -> Anchors:
    """Read an anchors CSV: a header ``id,x,y,z`` and one anchor per row (metres).

    Args:
        path: the file.

    Returns:
        The anchors in file order; ``source`` is the path.

    Raises:
        ReaderError: the file is missing or unreadable, has no header or lacks a column, a
            row has the wrong number of cells, a coordinate is not a finite number, an id is
            empty or repeated, or fewer than three anchors are listed.
    """
    path = Path(path)
    where = str(path)
    header_line, headers, rows, lines = _read_rows(load_text(path), where=where, kind="anchors")
    cols = _choose(headers, _ANCHOR_NAMES, ("id", "x", "y", "z"), where=where, line=header_line)
    ids: list[str] = []
    positions = np.zeros((len(rows), 3))
    seen: dict[str, int] = {}
    for k, (row, line) in enumerate(zip(rows, lines, strict=True)):  # a few dozen anchors
        if len(row) != len(headers):
            msg = (
                f"{where}, line {line}: {len(row)} cells but the header has {len(headers)}; "
                "give every anchor an id, x, y and z."
            )
            raise ReaderError(msg)
        anchor_id = row[cols["id"]].strip()
        if not anchor_id:
            msg = f"{where}, line {line}: the anchor id is empty; give every anchor an id."
            raise ReaderError(msg)
        if anchor_id in seen:
            msg = (
                f"{where}, line {line}: anchor id {anchor_id!r} already used on line "
                f"{seen[anchor_id]}; give every anchor its own id."
            )
            raise ReaderError(msg)
        seen[anchor_id] = line
        for axis, key in enumerate(("x", "y", "z")):
            cell = row[cols[key]].strip()
            try:
                value = float(cell)
            except ValueError:
                value = float("nan")
            if not (np.isfinite(value) and abs(value) <= MAX_COORDINATE_M):
                msg = (
                    f"{where}, line {line}: {key} of anchor {anchor_id!r} is {cell!r}, not a "
                    "finite number of metres; survey the anchor or remove its row."
                )
                raise ReaderError(msg)
            positions[k, axis] = value
        ids.append(anchor_id)
    if len(ids) < MIN_ANCHORS:
        msg = (
            f"{where}: {len(ids)} anchors, but positioning needs at least {MIN_ANCHORS}; "
            "list every anchor of the installation."
        )
        raise ReaderError(msg)
    return Anchors(tuple(ids), positions, source=where)


def read_ranges(path: Path, anchors: Anchors) -> Ranges:
    """Read a ranges CSV: a header ``t,anchor_id,range_m[,rssi]`` and one range per row.

    Args:
        path: the file.
        anchors: the anchors the ids refer to.

    Returns:
        The usable measurements sorted by time (stable: file order within a stamp), with
        a warning naming how many rows were dropped and why.

    Raises:
        ReaderError: the file is missing or unreadable, has no header or lacks a column,
            the time unit is unknown, or no row is usable.
    """
    path = Path(path)
    where = str(path)
    header_line, headers, rows, lines = _read_rows(load_text(path), where=where, kind="ranges")
    cols = _choose(
        headers, _RANGE_NAMES, ("t", "anchor_id", "range_m"), where=where, line=header_line
    )
    ns_per_unit = _time_scale(headers[cols["t"]], where=where)
    total = len(rows)
    width = len(headers)
    if not total:
        msg = f"{where}: a header but no range rows; check that the file holds the recording."
        raise ReaderError(msg)
    shaped: BoolArray = np.fromiter((len(r) == width for r in rows), dtype=bool, count=total)
    fill = [""] * width
    padded = (r if ok else fill for r, ok in zip(rows, shaped, strict=True))
    columns = list(zip(*padded, strict=True))
    t_cells = columns[cols["t"]]
    t_raw = _floats(t_cells)
    range_raw = _floats(columns[cols["range_m"]])
    id_cells = np.array([c.strip() for c in columns[cols["anchor_id"]]], dtype=object)
    rssi = _floats(columns[cols["rssi"]]) if "rssi" in cols else None
    known = {anchor_id: k for k, anchor_id in enumerate(anchors.ids)}
    index = np.fromiter((known.get(c, -1) for c in id_cells), dtype=np.intp, count=total)
    limit = float(np.iinfo(np.int64).max) / ns_per_unit
    bad_time = shaped & ~(np.abs(t_raw) < limit)
    bad_range = shaped & ~bad_time & ~np.isfinite(range_raw)
    with np.errstate(invalid="ignore"):
        too_far = shaped & ~bad_time & ~bad_range & (np.abs(range_raw) > MAX_COORDINATE_M)
    bad_range |= too_far
    negative = shaped & ~bad_time & ~bad_range & (range_raw < 0)
    unknown = shaped & ~bad_time & ~bad_range & ~negative & (index < 0)
    keep = shaped & ~bad_time & ~bad_range & ~negative & ~unknown
    reasons = [
        (int((~shaped).sum()), f"with other than {width} cells"),
        (int(bad_time.sum()), "whose time is not a finite number"),
        (int((bad_range & ~too_far).sum()), "whose range is NaN or not a number"),
        (int(too_far.sum()), f"whose range is beyond {MAX_COORDINATE_M:g} m"),
        (int(negative.sum()), "with a negative range"),
        (int(unknown.sum()), "with an anchor id not in the anchors file"),
    ]
    notes: list[str] = []
    dropped = total - int(keep.sum())
    if dropped:
        parts = [f"{count} {why}" for count, why in reasons if count]
        names = sorted(set(id_cells[unknown].tolist()))
        if names:
            quoted = ", ".join(repr(n) for n in names[:_NAMED_IDS])
            more = f" and {len(names) - _NAMED_IDS} more" if len(names) > _NAMED_IDS else ""
            parts[-1] += f" ({quoted}{more})"
        first = int(lines[int(np.flatnonzero(~keep)[0])])
        notes.append(
            f"{where}: {dropped} of {total} range rows dropped (first at line {first}): "
            f"{'; '.join(parts)}."
        )
    if not keep.any():
        msg = (
            f"{where}: none of the {total} range rows is usable ({'; '.join(notes) or 'empty'}); "
            "check the columns t, anchor_id, range_m and that the ids match the anchors file."
        )
        raise ReaderError(msg)
    stamps = _exact_stamps(t_cells, t_raw, keep, int(ns_per_unit))
    order = np.argsort(stamps, kind="stable")
    return Ranges(
        anchors=anchors,
        stamps_ns=stamps[order],
        anchor_index=index[keep][order],
        range_m=range_raw[keep][order],
        rssi=None if rssi is None else rssi[keep][order],
        source=where,
        warnings=tuple(notes),
    )


def _exact_stamps(
    cells: Sequence[str], values: FloatArray, keep: BoolArray, ns_per_unit: int
) -> StampsNs:
    """Return the kept stamps in nanoseconds, exact for plain decimals such as ``1.000000005``.

    Float seconds near 1.7e9 resolve only about 240 ns, so plain decimal cells are read as
    integers (whole part, then the fraction's digits down to the nanosecond; further digits
    are cut); other spellings (``1e9``) go through the float value.
    """
    out: StampsNs = np.rint(values[keep] * ns_per_unit).astype(np.int64)
    text = np.char.strip(np.asarray(cells, dtype=str)[keep])
    negative = np.char.startswith(text, "-")
    parts = np.char.partition(np.char.lstrip(text, "+-"), ".")
    whole, frac = parts[:, 0], parts[:, 2]
    plain = (np.char.isdigit(whole) | (whole == "")) & (np.char.isdigit(frac) | (frac == ""))
    if not plain.any():
        return out
    digits = len(str(ns_per_unit)) - 1  # units are powers of ten of a nanosecond
    whole_ns = np.where(whole[plain] == "", "0", whole[plain]).astype(np.int64) * ns_per_unit
    frac_ns = np.zeros(whole_ns.shape[0], dtype=np.int64)
    if digits:
        padded = np.char.ljust(frac[plain], digits, "0").astype(f"<U{digits}")
        frac_ns = padded.astype(np.int64)
    out[plain] = np.where(negative[plain], -1, 1) * (whole_ns + frac_ns)
    return out


def _floats(cells: Sequence[str]) -> FloatArray:
    """Parse cells as float64; a cell that is not a number becomes NaN."""
    try:
        out: FloatArray = np.array(cells, dtype=np.float64)
    except ValueError:
        # Only files with a bad cell take this path: find which cells are bad.
        out = np.fromiter((_float_or_nan(c) for c in cells), dtype=np.float64, count=len(cells))
    return out


def _float_or_nan(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return float("nan")


def _read_rows(
    text: str, *, where: str, kind: str
) -> tuple[int, list[str], list[list[str]], IntArray]:
    """Return (header line, header cells, data rows, their 1-based lines)."""
    header: tuple[int, str] | None = None
    body_start = 0
    stream = io.StringIO(text)
    for number, raw in enumerate(stream, start=1):
        line = raw.strip()
        if line and not (line.startswith("#") and header is None and _is_comment(line)):
            header = (number, line)
            body_start = stream.tell()
            break
    if header is None:
        msg = f"{where}: the {kind} file is empty; it needs a header row and one row per entry."
        raise ReaderError(msg)
    header_line, header_text = header
    sep = _delimiter_of(header_text)
    headers = [c.strip() for c in split_line(header_text.lstrip("#"), sep, where=where)]
    if sum(_is_number(c) for c in headers) >= 2:  # no header has two numbers as names
        expected = "id,x,y,z" if kind == "anchors" else "t,anchor_id,range_m"
        msg = (
            f"{where}, line {header_line}: numbers but no header row; add a header such as "
            f"{expected}."
        )
        raise ReaderError(msg)
    body = text[body_start:].splitlines()
    numbered = [
        (number, raw)
        for number, raw in enumerate(body, start=header_line + 1)
        if raw.strip() and not raw.lstrip().startswith("#")
    ]
    lines = [number for number, _ in numbered]
    raws = [raw.strip() for _, raw in numbered]
    rows = [r.split() for r in raws] if sep is None else csv_rows(raws, sep, where=where)
    return header_line, headers, rows, np.array(lines, dtype=np.intp)


def _is_comment(line: str) -> bool:
    """A ``#`` line is a comment unless it is the header written as ``# id,x,y,z``.

    A header names at least two known columns; a remark such as ``# anchor survey`` does not.
    """
    cells = re.split(r"[,;\t\s]+", line.lstrip("#").strip())
    wanted = {n for names in (*_ANCHOR_NAMES.values(), *_RANGE_NAMES.values()) for n in names}
    known = 0
    for cell in cells:
        name = _normalize(cell)[0]
        base, sep, suffix = name.rpartition("_")
        known += name in wanted or bool(sep and suffix in _UNIT_SPELLINGS and base in wanted)
    return known < 2


def _delimiter_of(header: str) -> str | None:
    """Return the survey delimiter the header line holds most of, or None (whitespace)."""
    delimiter = max(SURVEY_DELIMITERS, key=header.count)
    return delimiter if header.count(delimiter) else None


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _normalize(header: str) -> tuple[str, str | None]:
    """Return (lower-case name without unit, unit or None) of a header cell."""
    name = header.strip().strip('"').strip().lstrip("#").strip().lower()
    unit = None
    match = _UNIT_RE.match(name)
    if match:
        name, unit = match["name"].strip(), match["unit"].strip()
    return re.sub(r"[\s\-]+", "_", name), unit


def _choose(
    headers: list[str],
    names: dict[str, tuple[str, ...]],
    required: tuple[str, ...],
    *,
    where: str,
    line: int,
) -> dict[str, int]:
    """Return the column index of every key found among the headers."""
    normalized = [_normalize(h)[0] for h in headers]
    chosen: dict[str, int] = {}
    for key, candidates in names.items():
        for candidate in candidates:
            found = [
                i for i, n in enumerate(normalized) if i not in chosen.values() and n == candidate
            ]
            if not found and key == "t":
                found = [
                    i
                    for i, n in enumerate(normalized)
                    if n.rpartition("_")[0] == candidate and n.rpartition("_")[2] in _UNIT_SPELLINGS
                ]
            if found:
                chosen[key] = found[0]
                break
    missing = [key for key in required if key not in chosen]
    if missing:
        msg = (
            f"{where}, line {line}: no column for {missing[0]!r} among {headers!r}; name the "
            f"columns {','.join(required)}."
        )
        raise ReaderError(msg)
    return chosen


def _time_scale(header: str, *, where: str) -> float:
    """Return nanoseconds per unit of the time column (seconds unless its name says)."""
    name, unit = _normalize(header)
    if unit is None:
        base, sep, suffix = name.rpartition("_")
        unit = suffix if sep and base and suffix in _UNIT_SPELLINGS else "s"
    canonical = _UNIT_SPELLINGS.get(unit)
    if canonical is None:
        msg = (
            f"{where}: unknown time unit {unit!r} in column {header!r}; use seconds or name "
            f"the unit as one of {', '.join(TIME_UNITS)}."
        )
        raise ReaderError(msg)
    return float(TIME_UNITS[canonical])
