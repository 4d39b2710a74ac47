"""``errors.csv``: every matched pose and its errors (the reference-system paper's Pathcompare).

One row per matched pose per estimate::

    estimate,stamp_ns,t_s,ref_x,ref_y,ref_z,est_x,est_y,est_z,ate_m,ate_deg,rpe_m,rpe_deg

- ``stamp_ns``: the matched stamp on the reference's clock (the estimate's stamp plus the
  time offset), integer nanoseconds; ``t_s``: seconds since the reference's first pose
  (the report's clock), exact to the nanosecond.
- ``ref_*``: the reference at that stamp; ``est_*``: the aligned estimate (metres).
- ``ate_m`` / ``ate_deg``: absolute trajectory error (translation, rotation); ``ate_deg``
  is empty for position-only sources.
- ``rpe_m`` / ``rpe_deg``: relative pose error of the RPE pair that starts at this pose;
  empty when no pair starts here (the last poses, or between consecutive segments).

Writing is vectorized: each numeric column becomes a fixed-width block of ASCII digits
computed with integer arithmetic on the whole column, the blocks are joined into one byte
matrix and the padding is squeezed out in one pass. There is no Python loop over rows, so
a million rows take well under a second.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from typing import Final

import numpy as np
from numpy.typing import NDArray

from exporters.options import ExportOptions
from loceval.core.arrays import FloatArray, StampsNs
from loceval.evaluation import EstimateResult, EvaluationResult

__all__ = [
    "ERRORS_CSV_COLUMNS",
    "errors_csv_chunks",
    "export_errors_csv",
    "read_ate_series",
    "read_error_series",
]

ERRORS_CSV_COLUMNS: Final = (
    "estimate",
    "stamp_ns",
    "t_s",
    "ref_x",
    "ref_y",
    "ref_z",
    "est_x",
    "est_y",
    "est_z",
    "ate_m",
    "ate_deg",
    "rpe_m",
    "rpe_deg",
)
"""The header of ``errors.csv``."""

POSITION_DECIMALS: Final = 6
"""Metres to the micrometre."""
ERROR_DECIMALS: Final = 6
"""Metres and degrees of error, six decimals."""
CHUNK_ROWS: Final = 1 << 16
"""Rows formatted at a time (bounds the temporary byte matrix to a few MB)."""

_PAD: Final = 0  # NUL never occurs in CSV text; it marks the padding squeezed out at the end
_ZERO: Final = ord("0")
_POW10: Final = 10 ** np.arange(19, dtype=np.int64)  # 1 .. 10**18: every int64 magnitude
_INT64_SAFE: Final = 9.0e18
_NS_PER_S: Final = 1_000_000_000

ByteMatrix = NDArray[np.uint8]


def _digits(magnitude: NDArray[np.int64], negative: NDArray[np.bool_], decimals: int) -> ByteMatrix:
    """Right-aligned ``[-]int.frac`` fields of non-negative integers scaled by 10**decimals.

    Returns an (N, W) byte matrix, padded with NUL where a shorter number leaves room.
    """
    n = magnitude.shape[0]
    largest = int(magnitude.max()) if n else 0
    int_digits = max(1, len(str(largest // 10**decimals)))
    total = int_digits + decimals
    if total > _POW10.size:  # pragma: no cover  (int64 has at most 19 digits)
        msg = f"Cannot format {total} digits."
        raise ValueError(msg)
    places = _POW10[:total][::-1]
    digit_values = (magnitude[:, None] // places) % 10
    digits = (digit_values + _ZERO).astype(np.uint8)
    if int_digits > 1:
        # Leading zeros of the integer part become padding (the last integer digit stays).
        leading = np.cumsum(digit_values[:, : int_digits - 1] != 0, axis=1) == 0
        digits[:, : int_digits - 1][leading] = _PAD
    width = 1 + int_digits + (1 + decimals if decimals else 0)
    out = np.full((n, width), _PAD, dtype=np.uint8)
    # The sign sits in the first column; once the padding is squeezed out it touches the
    # first digit.
    out[:, 0] = np.where(negative, ord("-"), _PAD)
    out[:, 1 : 1 + int_digits] = digits[:, :int_digits]
    if decimals:
        out[:, 1 + int_digits] = ord(".")
        out[:, 2 + int_digits :] = digits[:, int_digits:]
    return out


def _float_field(values: FloatArray, decimals: int) -> ByteMatrix:
    """Fixed-point text of (N,) floats; NaN (a missing value) becomes an empty field."""
    finite = np.isfinite(values)
    scaled = np.where(finite, np.abs(values), 0.0) * 10.0**decimals
    if scaled.size and float(scaled.max()) >= _INT64_SAFE:
        return _text_field([f"{v:.{decimals}f}" if np.isfinite(v) else "" for v in values])
    magnitude = np.rint(scaled).astype(np.int64)
    negative = (values < 0) & (magnitude > 0)
    out = _digits(magnitude, negative, decimals)
    out[~finite] = _PAD
    return out


def _int_field(values: NDArray[np.int64], decimals: int = 0) -> ByteMatrix:
    """Text of (N,) integers, optionally read as fixed-point with ``decimals`` (ns -> s)."""
    negative = values < 0
    return _digits(np.abs(values), negative, decimals)


def _text_field(texts: list[str]) -> ByteMatrix:
    """Left-aligned text cells (used for rare fallbacks only)."""
    encoded = [t.encode("utf-8") for t in texts]
    width = max((len(t) for t in encoded), default=0)
    out = np.full((len(encoded), max(width, 1)), _PAD, dtype=np.uint8)
    for row, text in enumerate(encoded):  # fallback path: values beyond int64 fixed point
        out[row, : len(text)] = np.frombuffer(text, dtype=np.uint8)
    return out


def _constant_field(text: bytes, n: int) -> ByteMatrix:
    if not text:
        return np.full((n, 1), _PAD, dtype=np.uint8)
    row = np.frombuffer(text, dtype=np.uint8)
    return np.broadcast_to(row, (n, row.size))


def _csv_cell(text: str) -> bytes:
    """One CSV cell, quoted when it needs to be (names with commas or quotes)."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([text])
    return buf.getvalue().rstrip("\n").encode("utf-8")


def _rows(columns: list[ByteMatrix]) -> bytes:
    """Join column blocks with commas and newlines and squeeze out the padding."""
    n = columns[0].shape[0]
    comma = np.full((n, 1), ord(","), dtype=np.uint8)
    newline = np.full((n, 1), ord("\n"), dtype=np.uint8)
    parts: list[ByteMatrix] = []
    for k, column in enumerate(columns):
        if k:
            parts.append(comma)
        parts.append(column)
    parts.append(newline)
    matrix = np.concatenate(parts, axis=1).ravel()
    text: bytes = matrix[matrix != _PAD].tobytes()
    return text


def _per_pose_rpe(e: EstimateResult) -> tuple[FloatArray, FloatArray]:
    """RPE per matched pose: the value of the pair starting there, NaN when none does."""
    n = len(e.association)
    rpe_m = np.full(n, np.nan)
    rpe_deg = np.full(n, np.nan)
    starts = e.rpe_index[:, 0]
    rpe_m[starts] = e.rpe_translation.values
    if e.rpe_rotation is not None:
        rpe_deg[starts] = e.rpe_rotation.values
    return rpe_m, rpe_deg


def _estimate_chunks(e: EstimateResult, name: str, t0_ns: int, chunk_rows: int) -> Iterator[bytes]:
    ref = e.association.reference
    aligned = e.aligned
    stamps: StampsNs = ref.stamps_ns
    n = stamps.shape[0]
    ate_deg = e.ate_rotation.values if e.ate_rotation is not None else np.full(n, np.nan)
    rpe_m, rpe_deg = _per_pose_rpe(e)
    cell = _csv_cell(name)
    for a in range(0, n, chunk_rows):
        b = min(a + chunk_rows, n)
        s = stamps[a:b]
        columns = [
            _constant_field(cell, b - a),
            _int_field(s),
            _int_field(s - np.int64(t0_ns), decimals=9),
            *(_float_field(ref.positions_xyz[a:b, i], POSITION_DECIMALS) for i in range(3)),
            *(_float_field(aligned.positions_xyz[a:b, i], POSITION_DECIMALS) for i in range(3)),
            _float_field(e.ate_translation.values[a:b], ERROR_DECIMALS),
            _float_field(ate_deg[a:b], ERROR_DECIMALS),
            _float_field(rpe_m[a:b], ERROR_DECIMALS),
            _float_field(rpe_deg[a:b], ERROR_DECIMALS),
        ]
        yield _rows(columns)


def errors_csv_chunks(result: EvaluationResult, *, chunk_rows: int = CHUNK_ROWS) -> Iterator[bytes]:
    """Yield ``errors.csv`` in pieces (the header first), for streaming to a file or socket.

    Args:
        result: the evaluation.
        chunk_rows: rows formatted per piece.

    Yields:
        UTF-8 CSV text.
    """
    yield (",".join(ERRORS_CSV_COLUMNS) + "\n").encode("ascii")
    t0_ns = int(result.reference.stamps_ns[0]) if len(result.reference) else 0
    for k, e in enumerate(result.estimates):
        yield from _estimate_chunks(e, e.name or f"estimate {k + 1}", t0_ns, chunk_rows)


def export_errors_csv(result: EvaluationResult, options: ExportOptions) -> bytes:
    """Return ``errors.csv``: every matched pose with reference, aligned estimate and errors.

    Args:
        result: the evaluation.
        options: unused (the table has no options); part of the exporter signature.

    Returns:
        The CSV as UTF-8 bytes (columns: :data:`ERRORS_CSV_COLUMNS`).
    """
    del options
    return b"".join(errors_csv_chunks(result))


def _estimate_rows(data: bytes, name: str) -> bytes | None:
    """Return an estimate's rows of ``errors.csv`` without their first cell (None: no rows).

    Vectorised: the rows are found by their first cell, quoted as written.

    Raises:
        ValueError: the file is not an ``errors.csv`` of this layout.
    """
    header, _, body = data.partition(b"\n")
    if header.decode("utf-8", "replace").strip() != ",".join(ERRORS_CSV_COLUMNS):
        msg = "Not an errors.csv of loceval: its header differs."
        raise ValueError(msg)
    prefix = _csv_cell(name) + b","
    lines = np.asarray(body.split(b"\n"), dtype=np.bytes_)
    mine = lines[np.char.startswith(lines, prefix)]
    if not mine.size:
        return None
    return b"\n".join(mine.tolist()).replace(b"\n" + prefix, b"\n")[len(prefix) :]


def read_ate_series(data: bytes, name: str) -> tuple[StampsNs, FloatArray]:
    """Read one estimate's ATE series back from an ``errors.csv`` this module wrote.

    Vectorised: the estimate's rows are found by their first cell (quoted as written) and
    their numbers parsed by :func:`numpy.loadtxt`; the stamps as int64, exactly.

    Args:
        data: the file's bytes.
        name: the estimate's name, as in the file's first column.

    Returns:
        ``(stamps_ns, ate_m)``, (N,) each, in the file's order; empty without rows.

    Raises:
        ValueError: the file is not an ``errors.csv`` of this layout.
    """
    block = _estimate_rows(data, name)
    if block is None:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.float64)
    ate_column = ERRORS_CSV_COLUMNS.index("ate_m") - 1
    stamps = np.loadtxt(io.BytesIO(block), delimiter=",", usecols=0, dtype=np.int64, ndmin=1)
    ate = np.loadtxt(io.BytesIO(block), delimiter=",", usecols=ate_column, ndmin=1)
    return stamps, ate


def read_error_series(data: bytes, name: str, column: str) -> tuple[StampsNs, FloatArray]:
    """Read one estimate's errors of one column (``ate_m``, ``rpe_m``) from ``errors.csv``.

    Rows whose cell is empty (no RPE pair starts there) are left out; vectorised as
    :func:`read_ate_series`.

    Args:
        data: the file's bytes.
        name: the estimate's name, as in the file's first column.
        column: ``ate_m``, ``ate_deg``, ``rpe_m`` or ``rpe_deg``.

    Returns:
        ``(stamps_ns, errors)``, (N,) each, in the file's order; empty without rows.

    Raises:
        ValueError: the file is not an ``errors.csv`` of this layout, or no such column.
    """
    if column not in ERRORS_CSV_COLUMNS[-4:]:
        msg = f"No error column {column!r} in errors.csv."
        raise ValueError(msg)
    block = _estimate_rows(data, name)
    if block is None:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.float64)
    index = ERRORS_CSV_COLUMNS.index(column) - 1
    stamps = np.loadtxt(io.BytesIO(block), delimiter=",", usecols=0, dtype=np.int64, ndmin=1)
    values = np.atleast_1d(
        np.genfromtxt(io.BytesIO(block), delimiter=",", usecols=[index], dtype=np.float64)
    )
    keep = np.isfinite(values)
    return stamps[keep], values[keep]
