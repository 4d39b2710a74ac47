"""``CommonObject.Encode()`` of plain polyline curves, written with NumPy and zlib.

``paths.3dm.json`` carries every ATE run of an estimate as the ``Encode()`` dict of a
``PolylineCurve`` (``{version, archive3dm, opennurbs, data}``, ``data`` the base64 of an
openNURBS archive of the curve). Built through rhino3dm, each of tens of thousands of runs
costs a ``Point3dList.Add`` per vertex, a curve and an ``Encode()`` call; the archive of a
polyline without user strings is a fixed layout around its coordinates, so it is written
here directly:

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
import functools
import struct
import zlib
from collections.abc import Sequence
from typing import Any, Final

import numpy as np
import rhino3dm as _rhino3dm

from loceval.core.arrays import FloatArray

rhino3dm: Any = _rhino3dm  # untyped (see exporters.cad.rhino)

__all__ = ["encode_polylines", "point_list", "polyline_curve"]

_CLASS: Final = 0x00027FFA
_CLASS_DATA: Final = 0x0002FFFC
_CLASS_ID: Final = bytes.fromhex(
    "fbff02001400000000000000"  # the class id chunk: typecode, length 20
    "e6d4d74e47e9d311bfe50010830122f0"  # ON_PolylineCurve's class UUID
    "4e9cbbdb"  # its CRC-32
)
_CLASS_END: Final = bytes.fromhex("ff7f02800000000000000000")
_DIMENSION: Final = struct.pack("<i", 3)
_SAMPLE: Final = np.array(
    [[1.5, -2.25, 3.0], [1e6 / 3, 7.0, -0.125], [-4.0, 5e-7, 1234567.891], [0.0, 0.0, 0.0]]
)


def point_list(vertices: FloatArray) -> Any:  # noqa: ANN401  (rhino3dm is untyped here)
    """Return a rhino3dm ``Point3dList`` of the (K, 3) ``vertices``."""
    points = rhino3dm.Point3dList(len(vertices))
    for x, y, z in vertices.tolist():  # rhino3dm takes points one by one
        points.Add(x, y, z)
    return points


def polyline_curve(vertices: FloatArray) -> Any:  # noqa: ANN401
    """Return a rhino3dm ``PolylineCurve`` through the (K, 3) ``vertices``."""
    return rhino3dm.PolylineCurve(point_list(vertices))


def encode_polylines(runs: Sequence[FloatArray]) -> list[dict[str, object]]:
    """Return the ``Encode()`` dict of a ``PolylineCurve`` through each (K, 3) vertex array.

    The curves carry no user strings. Byte for byte what rhino3dm's ``Encode()`` returns
    (checked once per process against rhino3dm; rhino3dm encodes them when it differs).
    """
    header = _header()
    if header is None:  # a rhino3dm that writes another layout: its own encoding
        return [polyline_curve(vertices).Encode() for vertices in runs]
    return [{**header, "data": _data(vertices)} for vertices in runs]  # one dict per curve


def _data(vertices: FloatArray) -> str:
    """Return the base64 archive of a polyline curve through ``vertices`` (see the module)."""
    n = len(vertices)
    count = struct.pack("<i", n)
    content = b"".join(
        (
            b"\x10",  # the class data's version: 1.0
            count,
            np.ascontiguousarray(vertices, dtype="<f8").tobytes(),
            count,
            np.arange(n, dtype="<f8").tobytes(),  # the parameters of the vertices
            _DIMENSION,
        )
    )
    inner = len(_CLASS_ID) + 12 + len(content) + 4 + len(_CLASS_END)
    archive = b"".join(
        (
            struct.pack("<Iq", _CLASS, inner),
            _CLASS_ID,
            struct.pack("<Iq", _CLASS_DATA, len(content) + 4),
            content,
            struct.pack("<I", zlib.crc32(content)),
            _CLASS_END,
        )
    )
    return base64.b64encode(archive).decode("ascii")


@functools.cache
def _header() -> dict[str, object] | None:
    """Return the fields around ``data`` when this encoding is rhino3dm's, else None."""
    reference = polyline_curve(_SAMPLE).Encode()
    if not isinstance(reference, dict) or reference.get("data") != _data(_SAMPLE):
        return None
    return {key: value for key, value in reference.items() if key != "data"}
