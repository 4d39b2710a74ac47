"""Shared parsing of whitespace and comma-separated trajectory tables.

:func:`load_text` reads a file (file errors, encodings) and :func:`parse_table` parses a
table of numbers: plain decimal tables with :mod:`loceval.readers._plain` (from the file's
bytes as :func:`load_bytes` reads them, when they are ASCII: no decoding), others with
NumPy's C parser (``np.loadtxt``) and, only when that fails, by walking the lines in Python
to name the exact line, cell and problem. :func:`stamps_from_values` turns
stamp columns into int64 nanoseconds. The readers on top are :mod:`loceval.readers.tum`,
:mod:`loceval.readers.euroc`, :mod:`loceval.readers.kitti`, :mod:`loceval.readers.csv` and
:mod:`loceval.readers.motive`; each finishes through
:func:`loceval.readers._common.build_trajectory` (NaN/inf, quaternion norms, sorting,
duplicates, at least three poses).
"""

from __future__ import annotations

import csv
import io
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import AnyStr, Final

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray, StampsNs
from loceval.errors import ReaderError
from loceval.readers._common import seconds_to_ns
from loceval.readers._plain import parse_plain
from loceval.readers.source import missing_file_error

__all__ = [
    "NS_PER_S",
    "SURVEY_DELIMITERS",
    "NumericTable",
    "csv_rows",
    "decode_text",
    "load_bytes",
    "load_text",
    "parse_table",
    "positions_and_quat",
    "split_line",
    "stamps_from_values",
]

NS_PER_S: Final = 1_000_000_000
SURVEY_DELIMITERS: Final = (",", ";", "\t")
"""The cell delimiters of the small survey tables (anchors, control points, visits, ranges)."""
_INT64_MAX: Final = float(np.iinfo(np.int64).max)
_NAN_SPELLINGS: Final = ("nan", "NaN", "NAN", "Nan")


@dataclass(frozen=True, slots=True, eq=False)
class NumericTable:
    """Numbers parsed from a text table, with the file line of every row.

    Attributes:
        values: (N, K) float64; NaN where a cell was empty (when empty cells are allowed).
        lines: (N,) 1-based line numbers in the file.
        empty: (N,) whether the row had an empty cell (all False unless allowed).
        first_int: (N,) the first column parsed exactly as int64, when asked for and every
            cell of it is an integer; else None.
    """

    values: FloatArray
    lines: IntArray
    empty: BoolArray
    first_int: StampsNs | None = None

    def __len__(self) -> int:
        """Return the number of rows."""
        return int(self.values.shape[0])


def load_text(path: Path) -> str:
    """Read a text file as UTF-8 (with or without BOM), falling back to Latin-1.

    Args:
        path: the file.

    Returns:
        The content, with old Mac CR-only line ends turned into LF.

    Raises:
        ReaderError: the file is missing, a folder, unreadable, or binary.
    """
    return decode_text(load_bytes(path))


def load_bytes(path: Path) -> bytes:
    """Read a text file's bytes, undecoded (:func:`parse_table` decodes them when needed).

    Raises:
        ReaderError: the file is missing, a folder, unreadable, or binary.
    """
    try:
        raw = path.read_bytes()
    except FileNotFoundError as err:
        raise missing_file_error(path) from err
    except IsADirectoryError as err:
        msg = (
            f"{str(path)!r} is a folder, not a trajectory file; name the file, or use "
            f"bag:{path}@TOPIC for a ROS 2 bag folder."
        )
        raise ReaderError(msg) from err
    except OSError as err:
        msg = f"Cannot read {str(path)!r} ({err.strerror}); check the path and its permissions."
        raise ReaderError(msg) from err
    if b"\x00" in raw[:4096]:
        msg = (
            f"{str(path)!r} is a binary file, not a text trajectory; for a bag name a topic, "
            f"e.g. bag:{path}@/odom."
        )
        raise ReaderError(msg)
    return raw


def decode_text(raw: bytes) -> str:
    """Decode a text file's bytes as :func:`load_text` reads them."""
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    if "\r" in text and "\n" not in text:
        text = text.replace("\r", "\n")
    return text


def csv_rows(lines: Sequence[str], delimiter: str, *, where: str) -> list[list[str]]:
    """Split lines into CSV cells (quotes honoured), as :func:`csv.reader` does.

    Args:
        lines: the lines, without their line ends.
        delimiter: the cell delimiter.
        where: the file, for the message.

    Returns:
        The cells of each line.

    Raises:
        ReaderError: a line is not CSV the csv module can split: a cell longer than its
            limit (128 KiB) or a line break inside a cell.
    """
    try:
        return list(csv.reader(lines, delimiter=delimiter))
    except csv.Error as err:
        msg = (
            f"{where} is not a readable CSV table ({err}); check that it is a text table "
            "with one row per line and cells of ordinary length."
        )
        raise ReaderError(msg) from err


def split_line(line: str, delimiter: str | None, *, where: str = "The table") -> list[str]:
    """Split a line at ``delimiter`` (CSV quoting), or at whitespace without one.

    Raises:
        ReaderError: not CSV the csv module can split (a huge cell, a stray line break).
    """
    if delimiter is None:
        return line.split()
    return csv_rows([line], delimiter, where=where)[0]


def parse_table(
    text: str | bytes,
    *,
    where: str,
    delimiter: str | None,
    hint: str,
    skip_lines: int = 0,
    usecols: Sequence[int] | None = None,
    names: Sequence[str] | None = None,
    comments: str | None = None,
    empty_cells: bool = False,
    int_first: bool = False,
) -> NumericTable:
    """Parse a table of numbers; on bad input, name the line and the cell.

    Blank lines, and with ``comments`` comment lines and trailing comments, are skipped.

    Args:
        text: the whole file, as text or as its bytes (:func:`load_bytes`: a table of
            plain ASCII numbers is parsed from them without decoding, anything else is
            decoded as :func:`load_text` does first).
        where: the file name used in messages.
        delimiter: the cell delimiter, or None for runs of whitespace.
        hint: what a line of this format holds, for the column-count message.
        skip_lines: lines at the top to skip (headers).
        usecols: the 0-based cells to read, in this order; None reads every cell and
            requires the same number on every line.
        names: the names of the read columns, for messages.
        comments: the comment character, or None.
        empty_cells: read empty cells as NaN and flag their rows (tracking lost) instead
            of rejecting them.
        int_first: also parse the first read column exactly as int64 (nanosecond stamps).

    Returns:
        The parsed table.

    Raises:
        ReaderError: a line has the wrong number of cells or a cell is not a number.
    """
    if isinstance(text, bytes) and not text.isascii():
        text = decode_text(text)
    if isinstance(text, bytes):  # ASCII: the bytes are the text, decoded only if need be
        first_line, first_pos = _skip_leading_lines(text, skip_lines, comments)
        body = text[first_pos:]
    else:  # ASCII text: character offsets are byte offsets, and the encoding is a copy
        first_line, first_pos = _skip_leading_lines(text, skip_lines, comments)
        body = text.encode()[first_pos:] if text.isascii() else text[first_pos:].encode()
    plain = parse_plain(body, delimiter=delimiter, usecols=usecols, int_first=int_first)
    if plain is not None:
        values, rows, first_int = plain
        numbered: IntArray = rows + (first_line + 1)
        return NumericTable(values, numbered, np.zeros(len(values), dtype=bool), first_int)
    if isinstance(text, bytes):
        text = decode_text(text)  # old Mac line ends become LF: the leading lines again
        first_line, first_pos = _skip_leading_lines(text, skip_lines, comments)
    # Without comments below the leading block the C parser need not look for them.
    body_comments = comments if comments and text.find(comments, first_pos) >= 0 else None
    fill = empty_cells and delimiter is not None
    # With empty cells written as NaN, a literal NaN would pass for one: the line pass
    # tells them apart.
    if not (fill and any(text.find(nan, first_pos) >= 0 for nan in _NAN_SPELLINGS)):
        source = _fill_empty_cells(text, delimiter) if fill and delimiter else text
        parsed = _parse_fast(
            source,
            delimiter=delimiter,
            skip_lines=first_line,
            usecols=usecols,
            comments=body_comments,
            int_first=int_first,
        )
        if parsed is not None:
            values, first_int = parsed
            lines = _data_line_numbers(text, first_line, first_pos, body_comments, len(values))
            if lines is not None:
                empty: BoolArray = np.zeros(len(values), dtype=bool)
                if fill:
                    empty = np.isnan(values).sum(axis=1) > 0
                return NumericTable(values, lines, empty, first_int)
    return _parse_slow(
        text,
        where=where,
        delimiter=delimiter,
        hint=hint,
        skip_lines=skip_lines,
        usecols=usecols,
        names=names,
        comments=comments,
        empty_cells=empty_cells,
        int_first=int_first,
    )


def stamps_from_values(
    values: FloatArray, *, ns_per_unit: float, lines: IntArray, where: str, unit: str
) -> StampsNs:
    """Convert float stamps in some unit to int64 nanoseconds, rejecting NaN and overflow.

    Args:
        values: (N,) stamps in ``unit``.
        ns_per_unit: nanoseconds per unit (1e9 for seconds).
        lines: (N,) line numbers for messages.
        where: the file name for messages.
        unit: the unit's name for messages.

    Returns:
        (N,) int64 nanoseconds, rounded to the nearest nanosecond.

    Raises:
        ReaderError: a stamp is NaN, inf, or beyond the int64 nanosecond range.
    """
    limit = _INT64_MAX / ns_per_unit
    bad = np.flatnonzero(~(np.abs(values) < limit))
    if bad.size:
        i = int(bad[0])
        value = float(values[i])
        hint = "fix that line or name the time unit"
        if unit == "s" and np.isfinite(value) and abs(value) > 1e15:
            hint = (
                "it looks like nanoseconds, but this format counts seconds: divide the "
                "stamps by 1e9, or use a CSV with a header and @time_unit=ns"
            )
        msg = f"{where}, line {int(lines[i])}: stamp {value!r} {unit} is not a usable time; {hint}."
        raise ReaderError(msg)
    if ns_per_unit == NS_PER_S:
        return seconds_to_ns(values)
    out: StampsNs = np.rint(values * ns_per_unit).astype(np.int64)
    return out


def positions_and_quat(
    values: FloatArray, width: int, *, quat_cols: list[int]
) -> tuple[FloatArray, FloatArray | None]:
    """Split ``t x y [z] [q...]`` rows into positions and quaternions.

    Args:
        values: (N, K) rows of a table.
        width: the number of used columns (3: ``t x y``, 4: ``t x y z``, 8 or more: poses).
        quat_cols: the four columns of the quaternion, in the order wanted.

    Returns:
        (N, 3) positions (z = 0 for ``t x y``) and (N, 4) quaternions, or None without them.
    """
    n = values.shape[0] if values.ndim == 2 else 0
    positions = np.zeros((n, 3))
    if n:
        xyz = min(width - 1, 3)
        positions[:, :xyz] = values[:, 1 : 1 + xyz]
    quat = values[:, quat_cols] if n and width >= 8 else None
    return positions, quat


def _fill_empty_cells(text: str, delimiter: str) -> str:
    """Write ``nan`` into empty cells so the C parser reads them (no literal NaN is present)."""
    d = delimiter
    out = text.replace(d + d, d + "nan" + d).replace(d + d, d + "nan" + d)
    out = out.replace("\n" + d, "\nnan" + d)
    out = out.replace(d + "\r\n", d + "nan\r\n").replace(d + "\n", d + "nan\n")
    if out.startswith(d):
        out = "nan" + out
    if out.endswith(d):
        out += "nan"
    return out


def _parse_fast(
    text: str,
    *,
    delimiter: str | None,
    skip_lines: int,
    usecols: Sequence[int] | None,
    comments: str | None,
    int_first: bool,
) -> tuple[FloatArray, StampsNs | None] | None:
    """Parse with ``np.loadtxt`` (C); None when it fails (then the line pass explains why)."""
    cols = list(usecols) if usecols is not None else None
    attempts = [True, False] if int_first else [False]
    encoded = text.encode()  # the C parser reads bytes faster than a StringIO's UCS-4
    for exact in attempts:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # "input contained no data" is a UserWarning
                if exact:
                    k = len(cols) if cols is not None else _count_cells(text, skip_lines, delimiter)
                    dtype = np.dtype([("i", np.int64), ("v", np.float64, (k - 1,))])
                    rec = np.loadtxt(
                        io.BytesIO(encoded),
                        dtype=dtype,
                        delimiter=delimiter,
                        comments=comments,
                        skiprows=skip_lines,
                        usecols=cols,
                        quotechar='"' if delimiter else None,
                        ndmin=1,
                    )
                    ints: StampsNs = np.ascontiguousarray(rec["i"])
                    values = np.column_stack([ints.astype(np.float64), rec["v"]])
                    return values, ints
                values = np.loadtxt(
                    io.BytesIO(encoded),
                    dtype=np.float64,
                    delimiter=delimiter,
                    comments=comments,
                    skiprows=skip_lines,
                    usecols=cols,
                    quotechar='"' if delimiter else None,
                    ndmin=2,
                )
                return values, None
        except (ValueError, UserWarning):
            continue
    return None


def _count_cells(text: str, skip_lines: int, delimiter: str | None) -> int:
    for index, raw in enumerate(io.StringIO(text)):
        line = raw.strip()
        if index >= skip_lines and line and not line.startswith("#"):
            return len(line.split(delimiter))
    return 1


def _skip_leading_lines(text: AnyStr, skip_lines: int, comments: str | None) -> tuple[int, int]:
    """Return (0-based line, offset) of the first line after ``skip_lines`` with data.

    Blank and comment lines right after the skipped ones (TUM headers) are passed over here,
    so that the data below them can often be numbered without a pass over every line. On
    bytes, offsets are byte offsets (the comment string is ASCII).
    """
    newline: AnyStr
    mark: AnyStr | None
    if isinstance(text, bytes):
        newline, mark = b"\n", None if comments is None else comments.encode()
    else:
        newline, mark = "\n", comments
    pos = 0
    for _ in range(skip_lines):
        pos = text.find(newline, pos) + 1
        if pos == 0:
            return skip_lines, len(text)
    line_index = skip_lines
    while pos < len(text):
        end = text.find(newline, pos)
        end = len(text) if end < 0 else end
        line = text[pos:end]
        if mark is not None:
            line = line.split(mark, 1)[0]
        if line.strip():
            break
        pos, line_index = end + 1, line_index + 1
    return line_index, pos


def _data_line_numbers(
    text: str, first_line: int, first_pos: int, comments: str | None, n_rows: int
) -> IntArray | None:
    """Return the 1-based line of each parsed row; None if it cannot be told for sure."""
    stop = len(text)
    while stop > first_pos and text[stop - 1].isspace():
        stop -= 1
    lines_left = text.count("\n", first_pos, stop) + 1 if first_pos < stop else 0
    if lines_left == n_rows:
        out: IntArray = np.arange(first_line + 1, first_line + 1 + n_rows, dtype=np.intp)
        return out
    # Blank or comment lines among the data: find the data lines one by one.
    kept = [
        i
        for i, line in enumerate(text[first_pos:stop].split("\n"))
        if (line.split(comments, 1)[0] if comments is not None else line).strip()
    ]
    if len(kept) != n_rows:
        return None
    out = np.asarray(kept, dtype=np.intp)
    return out + (first_line + 1)


def _parse_slow(
    text: str,
    *,
    where: str,
    delimiter: str | None,
    hint: str,
    skip_lines: int,
    usecols: Sequence[int] | None,
    names: Sequence[str] | None,
    comments: str | None,
    empty_cells: bool,
    int_first: bool,
) -> NumericTable:
    """Parse line by line in Python, raising on the first bad line."""
    cols = list(usecols) if usecols is not None else None
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    empty_rows: list[bool] = []
    ints: list[int] | None = [] if int_first else None
    expected: tuple[int, int] | None = None  # (cells per line, first line)
    for lineno, raw in enumerate(text.split("\n")[skip_lines:], start=skip_lines + 1):
        line = raw.split(comments, 1)[0] if comments is not None else raw
        if not line.strip():
            continue
        cells = _split_cells(line.rstrip("\r"), delimiter, where=where)
        if expected is None:
            expected = (len(cells), lineno)
        picked = _pick_cells(
            cells, cols, names, where=where, lineno=lineno, expected=expected, hint=hint
        )
        row, has_empty = _convert_cells(
            picked, where=where, lineno=lineno, names=names, empty_cells=empty_cells
        )
        if ints is not None:
            try:
                ints.append(int(picked[0].strip()))
            except ValueError:
                ints = None
        rows.append(row)
        line_numbers.append(lineno)
        empty_rows.append(has_empty)
    width = len(cols) if cols is not None else (expected[0] if expected else 0)
    values = np.array(rows, dtype=np.float64).reshape(len(rows), width)
    first_int = None
    if ints is not None and rows:
        try:
            first_int = np.array(ints, dtype=np.int64)
        except OverflowError:
            first_int = None
    return NumericTable(
        values,
        np.array(line_numbers, dtype=np.intp),
        np.array(empty_rows, dtype=bool),
        first_int,
    )


def _pick_cells(
    cells: list[str],
    cols: list[int] | None,
    names: Sequence[str] | None,
    *,
    where: str,
    lineno: int,
    expected: tuple[int, int],
    hint: str,
) -> list[str]:
    """Return the used cells of a line; without ``cols`` every line needs the same count."""
    if cols is None:
        if len(cells) != expected[0]:
            msg = (
                f"{where}, line {lineno}: {len(cells)} values, but line {expected[1]} has "
                f"{expected[0]} and {hint}; fix that line."
            )
            raise ReaderError(msg)
        return cells
    if len(cells) <= max(cols):
        missing = next(j for j, c in enumerate(cols) if c >= len(cells))
        msg = (
            f"{where}, line {lineno}: {len(cells)} cells, but column "
            f"{_column_name(names, missing)!r} is cell {cols[missing] + 1}; "
            "check the delimiter and that line."
        )
        raise ReaderError(msg)
    return [cells[c] for c in cols]


def _split_cells(line: str, delimiter: str | None, *, where: str) -> list[str]:
    if delimiter is None:
        return line.split()
    return csv_rows([line], delimiter, where=where)[0]


def _convert_cells(
    cells: list[str], *, where: str, lineno: int, names: Sequence[str] | None, empty_cells: bool
) -> tuple[list[float], bool]:
    row: list[float] = []
    has_empty = False
    for j, raw in enumerate(cells):
        cell = raw.strip()
        if not cell:
            if not empty_cells:
                msg = (
                    f"{where}, line {lineno}: column {_column_name(names, j)!r} is empty; "
                    "fill it or remove that line."
                )
                raise ReaderError(msg)
            has_empty = True
            row.append(float("nan"))
            continue
        try:
            row.append(float(cell))
        except ValueError:
            msg = (
                f"{where}, line {lineno}: {cell!r} in column {_column_name(names, j)!r} is not "
                "a number; fix or remove that line."
            )
            raise ReaderError(msg) from None
    return row, has_empty


def _column_name(names: Sequence[str] | None, j: int) -> str:
    return names[j] if names is not None and j < len(names) else str(j + 1)
