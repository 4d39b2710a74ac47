"""Binary records of many items assembled with NumPy: one buffer, no bytes object per item.

The .3dm writers lay out tens of thousands of small records (a curve's openNURBS archive,
an object record around it) whose fields are the same for every item or differ only in
length and content. :func:`interleave` places every field of every item in one pass per
field; :func:`fill_crc32` then writes the CRC-32 of each item's checked span (zlib has no
batch call, so that is the one step taken per item, in C).
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

from loceval.core.arrays import IntArray

__all__ = ["Bytes", "Field", "constant", "fill_crc32", "interleave", "rows", "spread"]

Bytes: TypeAlias = NDArray[np.uint8]
"""A flat uint8 array of bytes."""
Field: TypeAlias = tuple[Bytes, IntArray]
"""(every item's segment one after another, (R,) the length of each item's segment)."""


def constant(chunk: bytes, count: int) -> Field:
    """Return the field that gives each of ``count`` items the bytes ``chunk``."""
    flat = np.tile(np.frombuffer(chunk, dtype=np.uint8), count)
    return flat, np.full(count, len(chunk), dtype=np.intp)


def rows(array: NDArray[np.generic]) -> Field:
    """Return the field that gives item ``r`` the bytes of ``array[r]`` (a fixed size)."""
    width = array.itemsize * int(np.prod(array.shape[1:], dtype=np.intp))
    flat = np.ascontiguousarray(array).view(np.uint8).reshape(-1)
    return flat, np.full(len(array), width, dtype=np.intp)


def spread(starts: IntArray, lengths: IntArray) -> IntArray:
    """Return ``starts[r] + 0 .. lengths[r] - 1`` for every ``r``, one after another."""
    firsts = np.cumsum(lengths) - lengths
    out: IntArray = np.arange(int(lengths.sum()), dtype=np.intp) + np.repeat(
        starts - firsts, lengths
    )
    return out


def interleave(fields: Sequence[Field]) -> tuple[Bytes, IntArray]:
    """Return every item's fields in order, items one after another, and (R + 1,) offsets.

    Item ``r``'s record is its segment of the first field, then of the second, and so on;
    it spans ``out[offsets[r]:offsets[r + 1]]``.
    """
    sizes = np.sum([lengths for _, lengths in fields], axis=0, dtype=np.intp)
    offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.intp)
    out = np.empty(int(offsets[-1]), dtype=np.uint8)
    start = offsets[:-1].copy()
    for flat, lengths in fields:  # a handful of fields, each placed for every item at once
        out[spread(start, lengths)] = flat
        start += lengths
    return out, offsets


def fill_crc32(out: Bytes, starts: IntArray, stops: IntArray, at: IntArray) -> None:
    """Write the CRC-32 of ``out[starts[r]:stops[r]]`` as 4 little-endian bytes at ``at[r]``."""
    view = out.data  # a memoryview: its slices copy nothing
    crcs = np.array(
        [zlib.crc32(view[a:b]) for a, b in zip(starts.tolist(), stops.tolist(), strict=True)],
        dtype="<u4",
    )
    out[spread(at, np.full(len(at), 4, dtype=np.intp))] = crcs.view(np.uint8)
