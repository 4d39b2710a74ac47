"""3D polylines written in bulk: ezdxf builds the drawing, the vertices are spliced in as text.

ezdxf spends about 100 us on each VERTEX entity (an object, its attributes, its handle), so a
100,000-pose path took 20 s. Here ezdxf creates each 3D ``POLYLINE`` without vertices (its
handle, owner, layer, colours, XDATA and its ``SEQEND``) and reserves one handle per vertex
right away, in the order ezdxf itself would allocate them; after ezdxf has written the
drawing, the ``VERTEX`` records are inserted before each polyline's ``SEQEND`` with exactly
the group codes and number formatting ezdxf uses (``repr`` of the coordinates, the 3D
polyline vertex flag 32). The file is the one ezdxf would have written, byte for byte
(``tests/exporters/test_dxf.py`` checks that), in a fraction of the time.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from ezdxf.document import Drawing
from ezdxf.entities.polyline import Polyline
from ezdxf.layouts.layout import Modelspace

from loceval.core.arrays import FloatArray

__all__ = ["BulkPolylines"]

_VERTEX_FLAG_3D = 32


@dataclass(frozen=True, slots=True)
class _Pending:
    handle: str
    owner: str
    layer: str
    first_vertex_handle: int
    vertices: FloatArray


class BulkPolylines:
    """Collects 3D polylines whose vertices are written by :meth:`splice`."""

    def __init__(self, doc: Drawing) -> None:
        """Start an empty collection for ``doc``."""
        self._doc = doc
        self._pending: list[_Pending] = []

    def add(
        self, msp: Modelspace, vertices: FloatArray, dxfattribs: Mapping[str, object]
    ) -> Polyline:
        """Add a 3D polyline through ``vertices`` (N, 3) and return it (without vertices yet).

        Its vertices take the next N handles, as ``msp.add_polyline3d`` would give them.
        """
        polyline = msp.add_polyline3d([], dxfattribs=dict(dxfattribs))
        handles = self._doc.entitydb.handles
        first = int(str(handles), 16)
        handles.reset(f"{first + len(vertices):X}")
        self._pending.append(
            _Pending(
                handle=str(polyline.dxf.handle),
                owner=str(polyline.dxf.owner),
                layer=str(polyline.dxf.layer),
                first_vertex_handle=first,
                vertices=vertices,
            )
        )
        return polyline

    def splice(self, text: str) -> str:
        """Insert every collected polyline's VERTEX records into the written drawing ``text``.

        Raises:
            ValueError: a collected polyline is not in ``text`` (a bug).
        """
        cuts: list[tuple[int, str]] = []
        after = 0
        for item in self._pending:  # one iteration per polyline
            key = f"\n  0\nPOLYLINE\n  5\n{item.handle}\n"
            # ezdxf writes the polylines in the order they were added: searching on from the
            # previous one keeps this linear (from the top, 25,000 polylines took 13 s)
            start = text.find(key, after)
            if start < 0:
                start = text.find(key)  # written in another order after all
            seqend = text.find("\n  0\nSEQEND\n", start) if start >= 0 else -1
            if start < 0 or seqend < 0:
                msg = f"POLYLINE {item.handle} not found in the written drawing"
                raise ValueError(msg)
            cuts.append((seqend + 1, _vertex_records(item)))
            after = seqend
        cuts.sort()
        parts, last = [], 0
        for position, records in cuts:
            parts += [text[last:position], records]
            last = position
        parts.append(text[last:])
        return "".join(parts)


def _vertex_records(item: _Pending) -> str:
    """Return the VERTEX records of one polyline as ezdxf writes them.

    Built from C-level list operations: the coordinates' ``repr`` comes from one ``repr`` of
    the coordinate list, and the record pieces are interleaved by slice assignment, so no
    Python code runs per vertex.
    """
    n = len(item.vertices)
    middle = (
        f"\n330\n{item.owner}\n100\nAcDbEntity\n  8\n{item.layer}\n100\nAcDbVertex\n"
        "100\nAcDb3dPolylineVertex\n 10\n"
    )
    coords = repr(item.vertices.ravel().tolist())[1:-1].split(", ") if n else []
    first = item.first_vertex_handle
    parts = [""] * (9 * n)
    parts[0::9] = ["  0\nVERTEX\n  5\n"] * n
    parts[1::9] = map("%X".__mod__, range(first, first + n))
    parts[2::9] = [middle] * n
    parts[3::9] = coords[0::3]
    parts[4::9] = ["\n 20\n"] * n
    parts[5::9] = coords[1::3]
    parts[6::9] = ["\n 30\n"] * n
    parts[7::9] = coords[2::3]
    parts[8::9] = [f"\n 70\n{_VERTEX_FLAG_3D}\n"] * n
    return "".join(parts)
