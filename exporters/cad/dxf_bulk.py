"""3D polylines written in bulk: ezdxf builds the drawing, the vertices are spliced in as text.

ezdxf spends about 100 us on each VERTEX entity (an object, its attributes, its handle), so a
100,000-pose path took 20 s. Here ezdxf creates each 3D ``POLYLINE`` without vertices (its
handle, owner, layer, colours, XDATA and its ``SEQEND``) and reserves one handle per vertex
right away, in the order ezdxf itself would allocate them; after ezdxf has written the
drawing, the ``VERTEX`` records are inserted before each polyline's ``SEQEND`` with exactly
the group codes and number formatting ezdxf uses (``repr`` of the coordinates, the 3D
polyline vertex flag 32). A path cut into pieces of one colour each (the ATE layer: 25,000
pieces for a 50,000-pose estimate) goes further: ezdxf makes the first piece, the others are
written as text after it, polyline, vertices and ``SEQEND``, with the handles ezdxf would
have given them (:meth:`BulkPolylines.add_coloured`). The file is the one ezdxf would have
written, byte for byte (``tests/exporters/cad/test_dxf.py`` checks that), in a fraction of the
time.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from ezdxf.document import Drawing
from ezdxf.entities.polyline import Polyline
from ezdxf.layouts.layout import Modelspace

from loceval.core.arrays import FloatArray, IntArray

__all__ = ["BulkPolylines"]

_VERTEX_FLAG_3D = 32
_PARTS = 9  # the strings of one VERTEX record (:func:`_vertex_parts`)


@dataclass(frozen=True, slots=True)
class _Coloured:
    """A polyline written as text only, after the one ezdxf made before it."""

    handle: int
    aci: int
    true_color: int
    vertices: FloatArray


@dataclass(frozen=True, slots=True)
class _Pending:
    handle: str
    owner: str
    layer: str
    first_vertex_handle: int
    vertices: FloatArray
    following: tuple[_Coloured, ...] = ()


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

    def add_coloured(
        self,
        msp: Modelspace,
        layer: str,
        pieces: Sequence[tuple[FloatArray, int, int]],
    ) -> None:
        """Add one 3D polyline per ``(vertices, aci, true_color)`` piece on ``layer``.

        ezdxf makes the first (it places the run among the drawing's entities); the others
        exist only as text, written after it with the handles ezdxf would have given them
        (a polyline, its SEQEND, then its vertices), so a path cut into thousands of
        coloured pieces costs no entity object per piece.
        """
        if not pieces:
            return
        (vertices, aci, true_color), rest = pieces[0], pieces[1:]
        self.add(msp, vertices, {"layer": layer, "color": aci, "true_color": true_color})
        handles = self._doc.entitydb.handles
        next_handle = int(str(handles), 16)
        following = []
        for vertices, aci, true_color in rest:  # one iteration per piece
            following.append(_Coloured(next_handle, aci, true_color, vertices))
            next_handle += 2 + len(vertices)
        handles.reset(f"{next_handle:X}")
        self._pending[-1] = replace(self._pending[-1], following=tuple(following))

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
            if item.following:  # after the SEQEND record: the next record's "  0" line
                record_end = text.find("\n  0\n", seqend + 1) + 1
                cuts.append((record_end, _following_records(item)))
        cuts.sort()
        parts, last = [], 0
        for position, records in cuts:
            parts += [text[last:position], records]
            last = position
        parts.append(text[last:])
        return "".join(parts)


def _following_records(item: _Pending) -> str:
    """Return the records of the text-only polylines after ``item``, as ezdxf writes them.

    Every piece's records are laid into one list of strings by index (a polyline, its
    vertices, its SEQEND), with the vertices' text made for all pieces at once
    (:func:`_vertex_parts`), so no Python code runs per vertex.
    """
    pieces = item.following
    if not pieces:
        return ""
    counts = np.array([len(p.vertices) for p in pieces], dtype=np.intp)
    before = np.cumsum(counts) - counts  # vertices of the pieces before each
    index = np.arange(len(pieces))
    # each vertex's handle: its piece's handle + 2 (the polyline, its SEQEND) + its place
    handles = np.repeat(np.array([p.handle for p in pieces]) + 2 - before, counts)
    handles += np.arange(int(counts.sum()))
    vertices = np.concatenate([p.vertices for p in pieces])
    parts = np.empty(_PARTS * len(vertices) + 2 * len(pieces), dtype=object)
    starts = _PARTS * before + 2 * index  # where each piece's polyline record goes
    parts[starts] = [
        f"  0\nPOLYLINE\n  5\n{p.handle:X}\n330\n{item.owner}\n100\nAcDbEntity\n"
        f"  8\n{item.layer}\n 62\n{p.aci}\n420\n{p.true_color}\n"
        "100\nAcDb3dPolyline\n 66\n1\n 10\n0.0\n 20\n0.0\n 30\n0.0\n 70\n8\n"
        for p in pieces  # one per piece
    ]
    parts[starts + 1 + _PARTS * counts] = [
        f"  0\nSEQEND\n  5\n{p.handle + 1:X}\n330\n{p.handle:X}\n100\nAcDbEntity\n"
        f"  8\n{item.layer}\n"
        for p in pieces
    ]
    # the vertices fill the slots between, in order
    vertex_slots = np.ones(len(parts), dtype=bool)
    vertex_slots[starts] = False
    vertex_slots[starts + 1 + _PARTS * counts] = False
    parts[vertex_slots] = _vertex_parts(handles, item.owner, item.layer, vertices)
    return "".join(parts.tolist())


def _vertex_records(item: _Pending) -> str:
    """Return the VERTEX records of one polyline as ezdxf writes them."""
    return _vertex_text(item.first_vertex_handle, item.owner, item.layer, item.vertices)


def _vertex_text(first: int, owner: str, layer: str, vertices: FloatArray) -> str:
    """Return the VERTEX records of vertices (N, 3) with handles from ``first``."""
    handles = np.arange(first, first + len(vertices))
    return "".join(_vertex_parts(handles, owner, layer, vertices))


def _vertex_parts(handles: IntArray, owner: str, layer: str, vertices: FloatArray) -> list[str]:
    """Return the VERTEX records of vertices (N, 3) with their handles, in nine parts each.

    Built from C-level list operations: the coordinates' ``repr`` comes from one ``repr`` of
    the coordinate list, and the record pieces are interleaved by slice assignment, so no
    Python code runs per vertex.
    """
    n = len(vertices)
    middle = (
        f"\n330\n{owner}\n100\nAcDbEntity\n  8\n{layer}\n100\nAcDbVertex\n"
        "100\nAcDb3dPolylineVertex\n 10\n"
    )
    coords = repr(vertices.ravel().tolist())[1:-1].split(", ") if n else []
    parts = [""] * (_PARTS * n)
    parts[0::9] = ["  0\nVERTEX\n  5\n"] * n
    parts[1::9] = map("%X".__mod__, handles.tolist())
    parts[2::9] = [middle] * n
    parts[3::9] = coords[0::3]
    parts[4::9] = ["\n 20\n"] * n
    parts[5::9] = coords[1::3]
    parts[6::9] = ["\n 30\n"] * n
    parts[7::9] = coords[2::3]
    parts[8::9] = [f"\n 70\n{_VERTEX_FLAG_3D}\n"] * n
    return parts
