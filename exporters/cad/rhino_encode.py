"""``CommonObject.Encode()`` of plain polyline curves, written with NumPy and zlib.

``paths.3dm.json`` carries every ATE run of an estimate as the ``Encode()`` dict of a
``PolylineCurve`` (``{version, archive3dm, opennurbs, data}``, ``data`` the base64 of an
openNURBS archive of the curve), and ``paths.3dm`` stores the same archive in each run's
object record. Built through rhino3dm, each of tens of thousands of runs costs a
``Point3dList.Add`` per vertex, a curve and an ``Encode()`` call; the archive of a
polyline without user strings is a fixed layout around its coordinates, so it is written
here directly, every curve of a path in one buffer (:func:`polyline_archives`):

- an ``OPENNURBS_CLASS`` chunk (typecode ``0x00027ffa``, 8-byte length) holding
- the class id chunk (``0x0002fffb``: ``ON_PolylineCurve``'s UUID and its CRC-32),
- the class data chunk (``0x0002fffc``): version byte ``0x10``, the point count, the
  points as little-endian doubles, the count again, the parameters ``0 .. n-1``, the
  dimension 3, then the CRC-32 of that content,
- and the ``OPENNURBS_CLASS_END`` chunk (``0x80027fff``, length 0).

The first use compares this encoding with rhino3dm's own ``Encode()`` of a sample curve,
byte for byte; if a rhino3dm release writes anything else, every curve is encoded by
rhino3dm as before (:func:`encode_polylines` gives the same result either way).
"""

from __future__ import annotations

import base64
import binascii
import functools
import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import rhino3dm as _rhino3dm

from exporters.cad.jsondoc import JSONItems
from exporters.cad.records import Bytes, constant, fill_crc32, interleave, rows
from loceval.core.arrays import FloatArray, IntArray

rhino3dm: Any = _rhino3dm  # untyped (see exporters.cad.rhino)

__all__ = [
    "PolylineArchives",
    "curve_items_json",
    "decoded_polyline",
    "encode_polylines",
    "point_list",
    "polyline_archives",
    "polyline_curve",
]

_CLASS: Final = 0x00027FFA
_CLASS_DATA: Final = 0x0002FFFC
_CLASS_ID: Final = bytes.fromhex(
    "fbff02001400000000000000"  # the class id chunk: typecode, length 20
    "e6d4d74e47e9d311bfe50010830122f0"  # ON_PolylineCurve's class UUID
    "4e9cbbdb"  # its CRC-32
)
_CLASS_END: Final = bytes.fromhex("ff7f02800000000000000000")
_HEAD: Final = np.dtype(
    [
        ("class", "<u4"),
        ("class_length", "<i8"),
        ("class_id", f"V{len(_CLASS_ID)}"),
        ("data", "<u4"),
        ("data_length", "<i8"),
        ("version", "u1"),  # the class data's version: 1.0
        ("count", "<i4"),
    ]
)
"""Every archive's bytes up to its first coordinate (packed: no padding)."""
_CONTENT_AT: Final = 56  # the class data's content starts after three chunk headers and the id
_FIXED_CONTENT: Final = 13  # version, the count twice, the dimension
_SAMPLE: Final = np.array(
    [[1.5, -2.25, 3.0], [1e6 / 3, 7.0, -0.125], [-4.0, 5e-7, 1234567.891], [0.0, 0.0, 0.0]]
)


@dataclass(frozen=True, slots=True, eq=False)
class PolylineArchives:
    """The openNURBS archives of R polyline curves, one after another in one buffer.

    Attributes:
        data: every archive, curve after curve.
        offsets: (R + 1,) curve ``r``'s archive is ``data[offsets[r]:offsets[r + 1]]``.
        vertices: (V, 3) the curves' vertices, curve after curve.
        vertex_offsets: (R + 1,) curve ``r`` runs through ``vertices[vertex_offsets[r]:...]``.
    """

    data: Bytes
    offsets: IntArray
    vertices: FloatArray
    vertex_offsets: IntArray

    def __len__(self) -> int:
        """Return the number of curves."""
        return len(self.offsets) - 1

    def archive(self, index: int) -> bytes:
        """Return curve ``index``'s archive."""
        return self.data[self.offsets[index] : self.offsets[index + 1]].tobytes()

    def curve_vertices(self, index: int) -> FloatArray:
        """Return curve ``index``'s (K, 3) vertices."""
        out: FloatArray = self.vertices[self.vertex_offsets[index] : self.vertex_offsets[index + 1]]
        return out


def point_list(vertices: FloatArray) -> Any:  # noqa: ANN401  (rhino3dm is untyped here)
    """Return a rhino3dm ``Point3dList`` of the (K, 3) ``vertices``."""
    points = rhino3dm.Point3dList(len(vertices))
    for x, y, z in vertices.tolist():  # rhino3dm takes points one by one
        points.Add(x, y, z)
    return points


def polyline_curve(vertices: FloatArray) -> Any:  # noqa: ANN401
    """Return a rhino3dm ``PolylineCurve`` through the (K, 3) ``vertices``, point by point."""
    return rhino3dm.PolylineCurve(point_list(vertices))


def decoded_polyline(vertices: FloatArray) -> Any:  # noqa: ANN401
    """Return :func:`polyline_curve` of ``vertices``, decoded from its archive in one call.

    A path's piece of tens of thousands of vertices: one ``Decode`` instead of an ``Add``
    per vertex (the same curve; point by point when this rhino3dm writes another layout).
    """
    header = _header()
    if header is None:
        return polyline_curve(vertices)
    archives = polyline_archives(vertices, np.array([0, len(vertices)], dtype=np.intp))
    data = base64.b64encode(archives.data.data).decode("ascii")
    return rhino3dm.CommonObject.Decode({**header, "data": data})


def polyline_archives(vertices: FloatArray, offsets: IntArray) -> PolylineArchives:
    """Return the archive of a polyline curve through each run of (V, 3) ``vertices``.

    Args:
        vertices: the curves' vertices, curve after curve.
        offsets: (R + 1,) curve ``r`` runs through ``vertices[offsets[r]:offsets[r + 1]]``.

    Returns:
        The R archives (see the module), in one buffer.
    """
    points = np.ascontiguousarray(vertices, dtype="<f8")
    offsets = np.asarray(offsets, dtype=np.intp)
    counts = np.diff(offsets)
    n = len(counts)
    content = _FIXED_CONTENT + 32 * counts  # the class data chunk's content
    head = np.empty(n, dtype=_HEAD)
    head["class"] = _CLASS
    head["class_length"] = content + len(_CLASS_ID) + 12 + 4 + len(_CLASS_END)
    head["class_id"] = np.frombuffer(_CLASS_ID, dtype=head.dtype["class_id"])[0]
    head["data"] = _CLASS_DATA
    head["data_length"] = content + 4  # the content and its CRC
    head["version"] = 0x10
    head["count"] = counts
    # the parameters of the vertices: 0 .. n-1 along each curve
    params = np.arange(len(points), dtype="<f8") - np.repeat(offsets[:-1], counts)
    tail = np.int32(3).astype("<i4").tobytes() + bytes(4) + _CLASS_END  # dimension, CRC
    data, starts = interleave(
        [
            rows(head),
            (points.view(np.uint8).reshape(-1), 24 * counts),
            rows(counts.astype("<i4")),
            (params.view(np.uint8), 8 * counts),
            constant(tail, n),
        ]
    )
    first = starts[:-1] + _CONTENT_AT
    fill_crc32(data, first, first + content, first + content)
    return PolylineArchives(data, starts, points, offsets)


def encode_polylines(runs: Sequence[FloatArray]) -> list[dict[str, object]]:
    """Return the ``Encode()`` dict of a ``PolylineCurve`` through each (K, 3) vertex array.

    The curves carry no user strings. Byte for byte what rhino3dm's ``Encode()`` returns
    (checked once per process against rhino3dm; rhino3dm encodes them when it differs).
    """
    header = _header()
    if header is None:  # a rhino3dm that writes another layout: its own encoding
        return [polyline_curve(vertices).Encode() for vertices in runs]
    if not runs:
        return []
    offsets = np.concatenate(([0], np.cumsum([len(v) for v in runs]))).astype(np.intp)
    archives = polyline_archives(np.concatenate(runs), offsets)
    return [{**header, "data": data} for data in _base64(archives)]


def curve_items_json(
    archives: PolylineArchives, items: Sequence[Mapping[str, object]], which: IntArray
) -> JSONItems:
    """Return ``{**items[which[r]], "curve": Encode() of curve r}`` of every curve as JSON.

    Each is the text :func:`json.dumps` gives that dict (one compact line); the items are
    encoded once and every curve's base64 placed into them.
    """
    header = _header()
    if header is None:  # a rhino3dm that writes another layout: its own encoding
        return JSONItems(
            json.dumps({**items[k], "curve": polyline_curve(archives.curve_vertices(r)).Encode()})
            for r, k in enumerate(which.tolist())
        )
    # "\u0000" marks where the data goes: base64 needs no escapes, and no field holds it
    texts = [json.dumps({**item, "curve": {**header, "data": "\0"}}) for item in items]
    parts = [text.split('"\\u0000"') for text in texts]
    if any(len(p) != 2 for p in parts):  # a field holds the mark: each dict encoded
        return JSONItems(
            json.dumps({**items[k], "curve": {**header, "data": data}})
            for k, data in zip(which.tolist(), _base64(archives), strict=True)
        )
    before = [f'{p[0]}"' for p in parts]
    after = [f'"{p[1]}' for p in parts]
    return JSONItems(
        before[k] + data + after[k]
        for k, data in zip(which.tolist(), _base64(archives), strict=True)
    )


def _base64(archives: PolylineArchives) -> list[str]:
    """Return each curve's archive in base64."""
    view = archives.data.data  # a memoryview: its slices copy nothing
    return [
        binascii.b2a_base64(view[a:b], newline=False).decode("ascii")
        for a, b in itertools.pairwise(archives.offsets.tolist())
    ]


@functools.cache
def _header() -> dict[str, object] | None:
    """Return the fields around ``data`` when this encoding is rhino3dm's, else None."""
    reference = polyline_curve(_SAMPLE).Encode()
    archives = polyline_archives(_SAMPLE, np.array([0, len(_SAMPLE)], dtype=np.intp))
    if not isinstance(reference, dict) or reference.get("data") != _base64(archives)[0]:
        return None
    return {key: value for key, value in reference.items() if key != "data"}
