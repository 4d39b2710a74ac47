"""The ATE runs of a .3dm written in bulk: rhino3dm writes the model, the runs are spliced in.

rhino3dm spends about 40 us on each object of an ATE run (a ``Point3dList.Add`` per vertex,
the object added to the model, then written by ``File3dm.Write``): 25,000 runs of a
50,000-pose estimate took a second. Here rhino3dm adds only a placeholder per colour bin:
the first run of each bin, with its attributes (layer, name, colour) and an id of ours.
After rhino3dm has written the model, :func:`splice_runs` finds those object records in
the object table and puts every run's record in their place, in run order, each laid out
as rhino3dm lays out a placeholder of its bin:

- the object record chunk (``TCODE_OBJECT_RECORD``, ``0x20008070``, 8-byte length),
  holding
- the object type (``TCODE_OBJECT_RECORD_TYPE``, a short chunk: 4, a curve),
- the curve's openNURBS class chunk (:func:`exporters.cad.rhino_encode.polyline_archives`),
- the attributes chunk (``TCODE_OBJECT_RECORD_ATTRIBUTES``, ``0x02008072``): its chunk
  version byte, the object's id, then the bin's attributes as rhino3dm wrote them, and
  the CRC-32 of that content,
- and the record's end (``TCODE_OBJECT_RECORD_END``), then the record's own CRC-32, of
  nothing (everything in it sits in sub-chunks): 0.

The object table's length and the end-of-file chunk's file length are updated. Each
placeholder's record, rewritten this way with its own id, must equal what rhino3dm wrote
byte for byte; when it does not (or the file is laid out otherwise), :func:`splice_runs`
returns None and the caller has rhino3dm write every run, as before.
"""

from __future__ import annotations

import os
import struct
import uuid
import zlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np

from exporters.cad.records import Bytes, constant, fill_crc32, interleave, rows
from exporters.cad.rhino_encode import PolylineArchives
from loceval.core.arrays import IntArray

__all__ = ["RunBlock", "splice_runs"]

_CHUNK: Final = struct.Struct("<Iq")  # a chunk's typecode and its length (or short value)
_START: Final = 32  # the file's fixed header; its chunks follow
_OBJECT_TABLE: Final = 0x10000013
_OBJECT_RECORD: Final = 0x20008070
_RECORD_TYPE: Final = 0x82000071
_CLASS: Final = 0x00027FFA
_ATTRIBUTES: Final = 0x02008072
_RECORD_END_CODE: Final = 0x8200007F
_RECORD_END: Final = _CHUNK.pack(_RECORD_END_CODE, 0) + bytes(4)  # the end, then the record CRC
_CHUNK_ROW: Final = np.dtype([("code", "<u4"), ("length", "<i8")])
_END_OF_FILE: Final = 0x00007FFF
_SHORT: Final = 0x80000000
_ID: Final = slice(1, 17)  # the object id within the attributes' content (after its version)


@dataclass(frozen=True, slots=True, eq=False)
class RunBlock:
    """The ATE runs of one path, to be written where rhino3dm wrote their placeholders.

    Attributes:
        archives: each run's curve.
        bin_index: (R,) each run's ATE bin.
        placeholders: run index -> the id rhino3dm wrote that run's placeholder under (the
            first run of each bin, ``ATERunArrays.first_of_each_bin``, added in run order).
    """

    archives: PolylineArchives
    bin_index: IntArray
    placeholders: Mapping[int, uuid.UUID]


@dataclass(frozen=True, slots=True)
class _Record:
    start: int
    stop: int
    object_id: bytes


def splice_runs(data: bytes, blocks: Sequence[RunBlock]) -> bytes | None:
    """Return the .3dm ``data`` with each block's placeholders replaced by all of its runs.

    Returns:
        The file, or None when rhino3dm laid it out otherwise (see the module).
    """
    table = next((c for c in _chunks(data, _START, len(data)) if c[0] == _OBJECT_TABLE), None)
    end_of_file = (*_CHUNK.unpack_from(data, len(data) - 20), _int64(data, len(data) - 8))
    if table is None or end_of_file != (_END_OF_FILE, 8, len(data)):
        return None
    _, table_at, table_end = table
    records = list(_records(data, table_at + _CHUNK.size, table_end))
    where = {r.object_id: k for k, r in enumerate(records)}
    cuts: list[tuple[int, int, Bytes]] = []  # (start, stop) of placeholders, the runs
    for block in blocks:
        found = [where.get(object_id.bytes_le, -1) for object_id in block.placeholders.values()]
        if not found or found != list(range(found[0], found[0] + len(found))) or found[0] < 0:
            return None  # placeholders missing, or not one after another in run order
        placed = records[found[0] : found[-1] + 1]
        written = _block(block, [data[r.start : r.stop] for r in placed])
        if written is None:
            return None
        cuts.append((placed[0].start, placed[-1].stop, written))
    cuts.sort(key=lambda cut: cut[0])
    grown = sum(len(written) - (stop - start) for start, stop, written in cuts)
    out = bytearray(data[: table_at + 4])
    out += struct.pack("<q", _int64(data, table_at + 4) + grown)  # the table's length
    previous = table_at + _CHUNK.size
    for start, stop, written in cuts:
        out += data[previous:start]
        out += written.tobytes()
        previous = stop
    out += data[previous:]
    out[-8:] = struct.pack("<q", len(out))  # the end-of-file chunk's file length
    return bytes(out)


def _int64(data: bytes, at: int) -> int:
    value: int = struct.unpack_from("<q", data, at)[0]
    return value


def _block(block: RunBlock, placeholders: list[bytes]) -> Bytes | None:
    """Return the records of every run of ``block``, or None if a placeholder differs."""
    heads: set[bytes] = set()
    tails: dict[int, bytes] = {}  # bin -> its attributes' content after the id
    for (run, object_id), record in zip(block.placeholders.items(), placeholders, strict=True):
        parsed = _placeholder(record, object_id)
        if parsed is None:
            return None
        heads.add(parsed[0])
        tails[int(block.bin_index[run])] = parsed[1]
    if (
        len(heads) != 1
        or len(tails) != len(placeholders)
        or set(tails) != set(block.bin_index.tolist())
    ):
        return None
    written, offsets = _write(block, heads.pop(), tails)
    for run, record in zip(block.placeholders, placeholders, strict=True):
        if written[offsets[run] : offsets[run + 1]].tobytes() != record:
            return None
    return written


def _placeholder(record: bytes, object_id: uuid.UUID) -> tuple[bytes, bytes] | None:
    """Return a placeholder's (type chunk + attributes' version, attributes after the id).

    None when its record is not laid out as the module says.
    """
    code, length = _CHUNK.unpack_from(record)
    if code != _OBJECT_RECORD or length != len(record) - _CHUNK.size:
        return None
    parts = list(_chunks(record, _CHUNK.size, len(record) - 4))
    if [p[0] for p in parts] != [_RECORD_TYPE, _CLASS, _ATTRIBUTES, _RECORD_END_CODE]:
        return None
    (_, kind_at, kind_end), _, (_, at, stop), _ = parts
    content = record[at + _CHUNK.size : stop - 4]
    if (
        record[-len(_RECORD_END) :] != _RECORD_END
        or zlib.crc32(content) != int.from_bytes(record[stop - 4 : stop], "little")
        or content[_ID] != object_id.bytes_le
    ):
        return None
    return record[kind_at:kind_end] + content[: _ID.start], content[_ID.stop :]


def _write(block: RunBlock, head: bytes, tails: Mapping[int, bytes]) -> tuple[Bytes, IntArray]:
    """Lay out every run's record (see the module); return them and their (R + 1,) offsets.

    ``head`` is the object type chunk and the attributes' version byte; ``tails`` the
    attributes after the id, by bin.
    """
    kind, version = head[: _CHUNK.size], head[_CHUNK.size :]
    n = len(block.bin_index)
    curve = np.diff(block.archives.offsets)
    present = sorted(tails)
    which = np.searchsorted(present, block.bin_index)  # each run's bin among those present
    tail_length = np.array([len(tails[b]) for b in present], dtype=np.intp)[which]
    padded = np.zeros((len(present), max(len(t) for t in tails.values())), dtype=np.uint8)
    for k, b in enumerate(present):  # one per bin
        padded[k, : len(tails[b])] = np.frombuffer(tails[b], dtype=np.uint8)
    chosen = padded[which]
    content = len(version) + 16 + tail_length  # the attributes' content, before its CRC
    record = np.empty(n, dtype=_CHUNK_ROW)
    record["code"] = _OBJECT_RECORD
    record["length"] = len(kind) + curve + _CHUNK.size + content + 4 + len(_RECORD_END)
    attributes = np.empty(n, dtype=_CHUNK_ROW)
    attributes["code"] = _ATTRIBUTES
    attributes["length"] = content + 4
    written, offsets = interleave(
        [
            rows(record),
            constant(kind, n),
            (block.archives.data, curve),
            rows(attributes),
            constant(version, n),
            rows(_object_ids(block)),
            (chosen[np.arange(chosen.shape[1]) < tail_length[:, None]], tail_length),
            constant(bytes(4), n),  # the attributes' CRC, filled in below
            constant(_RECORD_END, n),
        ]
    )
    first = offsets[:-1] + _CHUNK.size + len(kind) + curve + _CHUNK.size
    fill_crc32(written, first, first + content, first + content)
    return written, offsets


def _object_ids(block: RunBlock) -> Bytes:
    """Return (R, 16) object ids as openNURBS writes them (``ON_UUID``'s little-endian fields).

    Random (version 4), one ``os.urandom`` call for all; the placeholders keep their own.
    """
    ids = np.frombuffer(os.urandom(16 * len(block.bin_index)), dtype=np.uint8).reshape(-1, 16)
    ids = ids.copy()
    ids[:, 7] = (ids[:, 7] & 0x0F) | 0x40  # Data3's high byte: the version, 4 (random)
    ids[:, 8] = (ids[:, 8] & 0x3F) | 0x80  # Data4[0]: the RFC 4122 variant
    for run, object_id in block.placeholders.items():  # a few: one per bin
        ids[run] = np.frombuffer(object_id.bytes_le, dtype=np.uint8)
    return ids


def _records(data: bytes, start: int, stop: int) -> Iterator[_Record]:
    """Yield each object record of the object table's content ``data[start:stop]``."""
    for code, at, end in _chunks(data, start, stop):
        if code != _OBJECT_RECORD:
            continue
        object_id = b""
        for inner, a, b in _chunks(data, at + _CHUNK.size, end - 4):
            if inner == _ATTRIBUTES:
                object_id = data[a + _CHUNK.size : b][_ID]
        yield _Record(at, end, object_id)


def _chunks(data: bytes, start: int, stop: int) -> Iterator[tuple[int, int, int]]:
    """Yield (typecode, start, stop) of each chunk in ``data[start:stop]``, one level deep."""
    at = start
    while at + _CHUNK.size <= stop:
        code, length = _CHUNK.unpack_from(data, at)
        end = at + _CHUNK.size + (0 if code & _SHORT else length)
        if length < 0 or end > stop:
            return
        yield code, at, end
        at = end
