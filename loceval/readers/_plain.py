"""A vectorised parser of plain numeric tables: the fast path of the text readers.

:func:`parse_plain` reads a table whose every cell is a decimal number such as ``-12.5``,
``.5``, ``3.`` or ``1.25e-3`` with NumPy array operations over the file's bytes instead of
a ``strtod`` call per cell. It gives bit-for-bit the values of ``np.loadtxt`` (and of
``float()``): every number is rounded correctly to the nearest double (ties to even).

A number is read as an integer significand ``M`` (at most 19 digits, so it fits in
``uint64``) and a decimal exponent ``E``; then

- ``E = 0``: ``M`` is converted to a double (one rounding);
- ``M < 2**53`` and ``|E| <= 22``: ``M`` and ``10**|E|`` are exact doubles, and one
  multiplication or division rounds correctly (Clinger 1990, "How to read floating point
  numbers accurately", the fast path);
- ``M >= 2**53`` and ``-22 <= E < 0`` (long stamps such as ``1700000000.005000114``):
  the quotient ``M / 10**-E`` is computed in double-double arithmetic (an exact remainder
  by Dekker's product, an error below 2**-40 units in the last place), and rounds
  correctly unless it lies within 2**-30 units in the last place of a halfway point.

Anything else (more digits, larger exponents, a value that close to a halfway point,
``nan``, ``inf``, comments, quotes, empty cells, rows of different lengths, a lone
carriage return) is left to the caller's general parser: :func:`parse_plain` returns None,
and never raises, so every error message stays that parser's.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Final, NamedTuple, cast

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from loceval.core.arrays import FloatArray, IntArray, StampsNs

__all__ = ["parse_plain"]

_DIGITS: Final = 20
"""Digit columns per number (a multiple of 4); numbers with more than 19 are not read here."""
_MAX_DIGITS: Final = 19
_TWO_53: Final = 2**53
_MAX_POW: Final = 22
_POW10: Final = np.array([10.0**k for k in range(_MAX_POW + 1)])
_EXP_DIGITS: Final = 3
"""Most digits of an exponent (``1e-300``)."""
_NUMBER_BYTES: Final = b"0123456789.+-eE"
_SPACE_BYTES: Final = b" \t\r\n"
_SPLIT: Final = 134217729.0  # 2**27 + 1: Dekker's splitting constant
_HALF_TOLERANCE: Final = 2.0**-30


def parse_plain(
    data: bytes,
    *,
    delimiter: str | None,
    usecols: Sequence[int] | None = None,
    int_first: bool = False,
) -> tuple[FloatArray, IntArray, StampsNs | None] | None:
    """Parse a table of plain decimal numbers, or return None to leave it to the C parser.

    Args:
        data: the table's bytes, from the first data line on (no header, no comments).
        delimiter: the cell delimiter (one character), or None for runs of whitespace.
        usecols: the 0-based cells to return, in this order; None returns every cell.
        int_first: also return the first returned column as exact int64 when every cell
            of it is an integer.

    Returns:
        ``(values, lines, first_int)``: (N, K) float64, the 0-based line of each row
        counted from the start of ``data``, and the exact first column (or None); None
        when the table holds anything this parser does not read.
    """
    delim = b"" if delimiter is None else delimiter.encode()
    if sys.byteorder != "little" or len(delim) > 1 or (delim and delim in _NUMBER_BYTES):
        return None
    if not data.isascii():
        return None
    parsed = _parse_chunks(data, delim=delim, want_ints=int_first)
    if parsed is None:
        return None
    parts: list[_Chunk] = []
    line = 0
    for part in parsed:
        if part.values.size:
            parts.append(part._replace(lines=part.lines + line))
        line += part.newlines
    if not parts or any(p.width != parts[0].width for p in parts):
        return None
    width = parts[0].width
    cols = list(range(width)) if usecols is None else list(usecols)
    if not cols or max(cols) >= width or min(cols) < -width:
        return None
    values = np.concatenate([p.values for p in parts]).reshape(-1, width)
    lines: IntArray = np.concatenate([p.lines for p in parts])
    table = values if usecols is None else values[:, cols]
    first_int = None
    if int_first:
        first = cols[0] % width
        if all(p.is_int is not None and p.is_int[first::width].all() for p in parts):
            first_int = np.concatenate([p.ints[first::width] for p in parts if p.ints is not None])
    return table, lines, first_int


_CHUNK_BYTES: Final = 1 << 19
"""Bytes per chunk: a chunk's temporaries stay in a core's L2 cache (measured on 21 MB of
TUM: 0.17 s in 512 KiB chunks, 0.18 s in 1 MiB, 0.20 s in 2 MiB, on one thread)."""
_THREADS_FROM: Final = 128
"""Tables of at least this many chunks (64 MiB) are parsed in threads: NumPy releases the GIL
in its array operations, so the chunks overlap on several cores (the values and line numbers
do not depend on it). Smaller tables are parsed on one thread: threads save wall time but
cost CPU time (measured on the 21 MB TUM file of 200,000 poses on two vCPUs: 0.14 s wall and
0.235 s CPU in two threads, 0.19 s wall and 0.19 s CPU on one), and below 64 MiB the wall time
saved is under a tenth of a second."""


def _parse_chunks(data: bytes, *, delim: bytes, want_ints: bool) -> list[_Chunk] | None:
    """Parse the table in chunks of whole lines, in order; None if one holds anything else.

    Chunks keep the temporaries small; many chunks are parsed in threads.
    """
    bounds = []
    lo = 0
    while lo < len(data):
        cut = data.find(b"\n", lo + _CHUNK_BYTES)
        hi = len(data) if cut < 0 else cut + 1
        bounds.append((lo, hi))
        lo = hi

    def parse(bound: tuple[int, int]) -> _Chunk | None:
        return _parse_chunk(data[bound[0] : bound[1]], delim=delim, want_ints=want_ints)

    workers = min(os.cpu_count() or 1, len(bounds) // 2)
    if len(bounds) < _THREADS_FROM or workers < 2:
        out = []
        for bound in bounds:
            part = parse(bound)
            if part is None:
                return None
            out.append(part)
        return out
    with ThreadPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(parse, bounds))
    return None if any(part is None for part in results) else cast("list[_Chunk]", results)


class _Chunk(NamedTuple):
    """The cells of a run of whole lines."""

    values: FloatArray
    lines: IntArray
    width: int
    newlines: int
    ints: StampsNs | None
    is_int: np.ndarray[tuple[int], np.dtype[np.bool_]] | None


def _parse_chunk(data: bytes, *, delim: bytes, want_ints: bool) -> _Chunk | None:
    """Parse whole lines (see parse_plain); None when they hold anything else."""
    b = np.frombuffer(data, dtype=np.uint8)
    newlines = np.flatnonzero(b == ord("\n"))
    if not _only_line_controls(b, data, newlines):
        return None
    inside = b > ord(" ")
    if delim:
        inside &= b != delim[0]
    edges = np.flatnonzero(inside[1:] != inside[:-1]) + 1
    if inside.size and inside[0]:
        edges = np.concatenate(([0], edges))
    if inside.size and inside[-1]:
        edges = np.concatenate((edges, [inside.size]))
    starts, ends = edges[0::2], edges[1::2]
    if starts.size == 0:
        return _Chunk(np.zeros(0), np.zeros(0, dtype=np.intp), 0, newlines.size, None, None)
    shape = _row_shape(b, starts, ends, newlines, delim=delim)
    if shape is None:
        return None
    lines, width = shape
    numbers = _numbers(b, data, starts, ends, want_ints=want_ints)
    if numbers is None:
        return None
    values, exact = numbers
    ints, is_int = (None, None) if exact is None else exact
    return _Chunk(values, lines, width, newlines.size, ints, is_int)


def _only_line_controls(
    b: np.ndarray[tuple[int], np.dtype[np.uint8]], data: bytes, newlines: IntArray
) -> bool:
    """Return whether the only control bytes are tabs, line feeds and CR before an LF."""
    allowed = newlines.size
    if b"\t" in data:
        allowed += int(np.count_nonzero(b == ord("\t")))
    if b"\r" in data:
        returns = np.flatnonzero(b == ord("\r"))
        follow = b[np.minimum(returns + 1, b.size - 1)]
        if (returns + 1 >= b.size).any() or (follow != ord("\n")).any():
            return False  # a lone carriage return: a line end to the C parser
        allowed += returns.size
    return int(np.count_nonzero(b < ord(" "))) == allowed


def _row_shape(
    b: np.ndarray[tuple[int], np.dtype[np.uint8]],
    starts: IntArray,
    ends: IntArray,
    newlines: IntArray,
    *,
    delim: bytes,
) -> tuple[IntArray, int] | None:
    """Return (0-based line of each row, cells per row), or None if rows differ."""
    n = starts.size
    bounds = np.concatenate(([0], np.searchsorted(starts, newlines), [n]))
    counts = np.diff(bounds)  # cells on each line
    used: IntArray = np.flatnonzero(counts)
    width = int(counts[used[0]])
    if (counts[used] != width).any():
        return None
    if delim:
        # Exactly one delimiter in each gap between two cells of a row, none elsewhere.
        found = np.flatnonzero(b == delim[0])
        if found.size != n - used.size:
            return None
        gap = np.ones(n - 1, dtype=bool)
        gap[bounds[used[1:]] - 1] = False
        within = np.flatnonzero(gap)
        if ((found < ends[within]) | (found >= starts[within + 1])).any():
            return None
    return used, width


def _owners(positions: IntArray, starts: IntArray, ends: IntArray) -> IntArray | None:
    """Return the token holding each position (at most one per token), or None."""
    if positions.size == starts.size:  # one per token: the common case, no search
        owner: IntArray = np.arange(starts.size)
        if ((positions < starts) | (positions >= ends)).any():
            return None
        return owner
    owner = np.searchsorted(ends, positions, side="right")
    if (np.diff(owner) <= 0).any():
        return None
    return owner


def _numbers(  # noqa: PLR0911  (each check that fails leaves the table to the C parser)
    b: np.ndarray[tuple[int], np.dtype[np.uint8]],
    data: bytes,
    starts: IntArray,
    ends: IntArray,
    *,
    want_ints: bool,
) -> tuple[FloatArray, tuple[StampsNs, np.ndarray[tuple[int], np.dtype[np.bool_]]] | None] | None:
    """Return each token's value (and its exact int64 with where that holds), or None."""
    first = b[starts]
    signed = (first == ord("-")) | (first == ord("+"))
    negative = first == ord("-")
    digit = (b - np.uint8(ord("0"))) < 10
    mant_end = ends
    exponent = None
    has_e = None
    if b"e" in data or b"E" in data:
        found = _exponents(b, starts, ends, signed, digit)
        if found is None:
            return None
        mant_end, exponent, has_e = found
    points = _points(b, data, starts, mant_end)
    if points is None:
        return None
    has_dot, frac = points
    n_digits = mant_end - starts - signed - has_dot
    if (n_digits < 1).any() or (n_digits > _MAX_DIGITS).any():
        return None
    # Every byte not accounted for as a sign, point or exponent must be a digit.
    if int(np.count_nonzero(digit)) != int(n_digits.sum()):
        return None
    significand = _significands(b, digit, n_digits)
    exp10 = -frac if exponent is None else exponent - frac
    values, unsure = _to_double(significand, exp10)
    if unsure.any():
        return None
    np.negative(values, out=values, where=negative)
    if not want_ints:
        return values, None
    # What the C parser reads as int64: no point, no exponent, within int64's range.
    is_int = ~has_dot & (significand <= np.uint64(2**63 - 1) + negative)
    if has_e is not None:
        is_int &= ~has_e
    ints: StampsNs = np.where(is_int, significand, np.uint64(0)).view(np.int64)
    np.negative(ints, out=ints, where=negative)  # -2**63 wraps onto itself
    return values, (ints, is_int)


def _points(
    b: np.ndarray[tuple[int], np.dtype[np.uint8]],
    data: bytes,
    starts: IntArray,
    mant_end: IntArray,
) -> tuple[np.ndarray[tuple[int], np.dtype[np.bool_]], IntArray] | None:
    """Return which tokens have a decimal point and their digits after it, or None.

    None when a point lies outside a token's significand or a token has two.
    """
    n = starts.size
    has_dot = np.zeros(n, dtype=bool)
    frac = np.zeros(n, dtype=np.int64)
    if b"." not in data:
        return has_dot, frac
    dots = np.flatnonzero(b == ord("."))
    if dots.size == n:  # a point in every number, the common case: no look-ups
        if ((dots < starts) | (dots >= mant_end)).any():
            return None
        has_dot[:] = True
        return has_dot, mant_end - dots - 1
    owner = _owners(dots, starts, mant_end)
    if owner is None or (dots < starts[owner]).any():
        return None
    has_dot[owner] = True
    frac[owner] = mant_end[owner] - dots - 1
    return has_dot, frac


def _exponents(
    b: np.ndarray[tuple[int], np.dtype[np.uint8]],
    starts: IntArray,
    ends: IntArray,
    signed: np.ndarray[tuple[int], np.dtype[np.bool_]],
    digit: np.ndarray[tuple[int], np.dtype[np.bool_]],
) -> tuple[IntArray, IntArray, np.ndarray[tuple[int], np.dtype[np.bool_]]] | None:
    """Find the ``e[sign]digits`` exponents; take their digits out of ``digit``.

    Returns:
        (end of each significand, decimal exponents, which tokens have one), or None
        when an exponent is malformed.
    """
    e_pos = np.flatnonzero((b == ord("e")) | (b == ord("E")))
    owner = _owners(e_pos, starts, ends)
    if owner is None or (e_pos <= starts[owner] + signed[owner]).any():
        return None
    token_end = ends[owner]
    after = b[np.minimum(e_pos + 1, b.size - 1)]
    e_signed = ((after == ord("-")) | (after == ord("+"))) & (e_pos + 1 < token_end)
    first_digit = e_pos + 1 + e_signed
    n_exp = token_end - first_digit
    if (n_exp < 1).any() or (n_exp > _EXP_DIGITS).any():
        return None
    value = np.zeros(e_pos.size, dtype=np.int64)
    for j in range(_EXP_DIGITS):  # at most three digits, for every exponent at once
        live = j < n_exp
        at = first_digit[live] + j
        if not digit[at].all():
            return None
        value[live] = value[live] * 10 + (b[at].astype(np.int64) - ord("0"))
        digit[at] = False  # not a digit of the significand
    n = starts.size
    mant_end = ends.copy()
    mant_end[owner] = e_pos
    exponent = np.zeros(n, dtype=np.int64)
    exponent[owner] = np.where(e_signed & (after == ord("-")), -value, value)
    has_e = np.zeros(n, dtype=bool)
    has_e[owner] = True
    return mant_end, exponent, has_e


_KEEP: Final = (
    (np.arange(_DIGITS) >= (_DIGITS - np.arange(_DIGITS + 1))[:, None]).astype(np.uint8) * 0xFF
).view(np.uint32)
"""Row ``k``: the masks of four digit bytes that keep the last ``k`` of the 20 digits."""


def _significands(
    b: np.ndarray[tuple[int], np.dtype[np.uint8]],
    digit: np.ndarray[tuple[int], np.dtype[np.bool_]],
    n_digits: IntArray,
) -> np.ndarray[tuple[int], np.dtype[np.uint64]]:
    """Return each token's significand: its digits (at most 19) as an integer."""
    count = int(n_digits.sum())
    stream = np.zeros(_DIGITS + count, dtype=np.uint8)
    np.compress(digit, b, out=stream[_DIGITS:])
    stream[_DIGITS:] -= np.uint8(ord("0"))
    ends = np.cumsum(n_digits)
    windows = sliding_window_view(stream, _DIGITS)[ends]  # right-aligned digits
    # Four digits per uint32 lane (little-endian: the first digit in the lowest byte).
    x = windows.view(np.uint32)
    x &= _KEEP.take(n_digits, axis=0)  # only this token's digits (take: quicker than [])
    pairs = (x & np.uint32(0x00FF00FF)) * np.uint32(10)
    x >>= np.uint32(8)
    x &= np.uint32(0x00FF00FF)
    pairs += x
    quads = (pairs & np.uint32(0xFFFF)) * np.uint32(100)
    pairs >>= np.uint32(16)
    quads += pairs
    out = quads[:, 0].astype(np.uint64)
    for j in range(1, _DIGITS // 4):
        out *= np.uint64(10_000)
        out += quads[:, j]
    return out


def _to_double(
    significand: np.ndarray[tuple[int], np.dtype[np.uint64]], exp10: IntArray
) -> tuple[FloatArray, np.ndarray[tuple[int], np.dtype[np.bool_]]]:
    """Return ``M * 10**E`` rounded to the nearest double, and where that is not sure."""
    values = significand.astype(np.float64)  # E = 0: one rounding
    small = significand < np.uint64(_TWO_53)
    negative = exp10 < 0
    unsure = (exp10 != 0) & ~((np.abs(exp10) <= _MAX_POW) & (small | negative))
    # Every value is scaled at once, by 10**|E| where one operation rounds correctly and by
    # 10**0 elsewhere (x * 1 and x / 1 are x): quicker than picking the values by a mask.
    scale = np.where(small, exp10, 0)
    if (scale > 0).any():
        values *= _POW10.take(scale, mode="clip")  # a negative E clips to 10**0
    np.negative(scale, out=scale)
    values /= _POW10.take(scale, mode="clip")
    long = np.flatnonzero(~small & negative & (exp10 >= -_MAX_POW))
    if long.size:
        quotient, doubtful = _long_quotient(significand.take(long), _POW10.take(-exp10.take(long)))
        values[long] = quotient
        unsure[long] = doubtful
    return values, unsure


def _long_quotient(
    m: np.ndarray[tuple[int], np.dtype[np.uint64]], d: FloatArray
) -> tuple[FloatArray, np.ndarray[tuple[int], np.dtype[np.bool_]]]:
    """Return ``m / d`` rounded to nearest for ``2**53 <= m < 2**64``, ``d = 10**k`` exact.

    ``m = mh + ml`` with ``mh`` its top 53 bits; ``q = fl(mh / d)``; the remainder
    ``mh - q d`` is a double and exact through Dekker's product; ``q + (r + ml) / d`` is
    summed exactly (Knuth's two-sum) into ``s + t``. The error left is below 2**-40 ulp,
    so ``s`` is the correctly rounded quotient unless ``|t|`` is that close to half an ulp
    (or ``s`` is a power of two, where the ulp changes): those are reported as doubtful.
    """
    mh = (m & ~np.uint64(0x7FF)).astype(np.float64)
    ml = (m & np.uint64(0x7FF)).astype(np.float64)
    q = mh / d
    p = q * d
    q_hi = _SPLIT * q
    q_hi = q_hi - (q_hi - q)
    q_lo = q - q_hi
    d_hi = _SPLIT * d
    d_hi = d_hi - (d_hi - d)
    d_lo = d - d_hi
    err = ((q_hi * d_hi - p) + q_hi * d_lo + q_lo * d_hi) + q_lo * d_lo
    remainder = (mh - p) - err
    c = (remainder + ml) / d
    s = q + c
    bb = s - q
    t = (q - (s - bb)) + (c - bb)
    half = np.spacing(s) / 2.0
    mantissa, _ = np.frexp(s)
    doubtful = (np.abs(np.abs(t) - half) <= half * _HALF_TOLERANCE) | (mantissa == 0.5)
    return s, doubtful
