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
have given them (:meth:`BulkPolylines.add_coloured`, from the runs' arrays: no object per
piece). The coordinates' text is made once per distinct number of the whole drawing (a run
repeats its neighbour's joining vertex and the estimate's own vertices). The file is the one
ezdxf would have written, byte for byte (``tests/exporters/cad/test_dxf.py`` checks that),
in a fraction of the time.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import overload

import numpy as np
from ezdxf.document import Drawing
from ezdxf.entities.polyline import Polyline
from ezdxf.layouts.layout import Modelspace

from loceval.core.arrays import FloatArray, IntArray

__all__ = ["BulkPolylines", "ColouredPieces"]

_VERTEX_FLAG_3D = 32
_PARTS = 9  # the strings of one VERTEX record (:func:`_vertex_parts`)


@dataclass(frozen=True, slots=True, eq=False)
class ColouredPieces(Sequence[tuple[FloatArray, int, int]]):
    """Polylines in colours, held as arrays: a sequence of ``(vertices, aci, true_color)``.

    Attributes:
        vertices: (V, 3) every piece's vertices, piece after piece.
        offsets: (R + 1,) piece ``r`` goes through ``vertices[offsets[r]:offsets[r + 1]]``.
        aci: (R,) each piece's AutoCAD colour index.
        true_color: (R,) each piece's 24-bit true colour.
    """

    vertices: FloatArray
    offsets: IntArray
    aci: IntArray
    true_color: IntArray

    @classmethod
    def of(cls, pieces: Iterable[tuple[FloatArray, int, int]]) -> ColouredPieces:
        """Return ``(vertices, aci, true_color)`` pieces as arrays."""
        listed = list(pieces)
        sizes = [len(vertices) for vertices, _, _ in listed]
        return cls(
            np.concatenate([v for v, _, _ in listed]) if listed else np.zeros((0, 3)),
            np.concatenate(([0], np.cumsum(sizes))).astype(np.intp),
            np.array([aci for _, aci, _ in listed], dtype=np.intp),
            np.array([true_color for _, _, true_color in listed], dtype=np.intp),
        )

    def __len__(self) -> int:
        """Return the number of pieces."""
        return len(self.aci)

    @overload
    def __getitem__(self, index: int) -> tuple[FloatArray, int, int]: ...

    @overload
    def __getitem__(self, index: slice) -> Sequence[tuple[FloatArray, int, int]]: ...

    def __getitem__(
        self, index: int | slice
    ) -> tuple[FloatArray, int, int] | Sequence[tuple[FloatArray, int, int]]:
        """Return piece ``index`` as ``(vertices, aci, true_color)`` (or a list of them)."""
        if isinstance(index, slice):
            return [self[k] for k in range(*index.indices(len(self)))]
        k = range(len(self))[index]
        vertices = self.vertices[self.offsets[k] : self.offsets[k + 1]]
        return vertices, int(self.aci[k]), int(self.true_color[k])

    def __iter__(self) -> Iterator[tuple[FloatArray, int, int]]:
        """Yield every piece as ``(vertices, aci, true_color)``."""
        return (self[k] for k in range(len(self)))


@dataclass(frozen=True, slots=True)
class _Pending:
    handle: str
    owner: str
    layer: str
    first_vertex_handle: int
    vertices: FloatArray
    following: ColouredPieces | None = None  # written as text after this polyline
    following_handle: int = 0  # the handle of the first of them


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
        coloured pieces costs no entity object per piece (:class:`ColouredPieces` hold
        them as arrays).
        """
        if not pieces:
            return
        if not isinstance(pieces, ColouredPieces):
            pieces = ColouredPieces.of(pieces)
        vertices, aci, true_color = pieces[0]
        self.add(msp, vertices, {"layer": layer, "color": aci, "true_color": true_color})
        following = ColouredPieces(
            pieces.vertices[pieces.offsets[1] :],
            pieces.offsets[1:] - pieces.offsets[1],
            pieces.aci[1:],
            pieces.true_color[1:],
        )
        handles = self._doc.entitydb.handles
        first = int(str(handles), 16)
        # each piece takes a handle for its polyline, its SEQEND and each vertex
        handles.reset(f"{first + 2 * len(following) + len(following.vertices):X}")
        self._pending[-1] = replace(self._pending[-1], following=following, following_handle=first)

    def splice(self, text: str) -> str:
        """Insert every collected polyline's VERTEX records into the written drawing ``text``.

        Raises:
            ValueError: a collected polyline is not in ``text`` (a bug).
        """
        coordinates = _coordinate_text(self._pending)
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
            cuts.append((seqend + 1, _vertex_records(item, next(coordinates))))
            after = seqend
            if item.following is not None:  # after the SEQEND record: the next "  0" line
                record_end = text.find("\n  0\n", seqend + 1) + 1
                cuts.append((record_end, _following_records(item, next(coordinates))))
        cuts.sort()
        parts, last = [], 0
        for position, records in cuts:
            parts += [text[last:position], records]
            last = position
        parts.append(text[last:])
        return "".join(parts)


def _coordinate_text(pending: list[_Pending]) -> Iterator[list[str]]:
    """Yield the coordinates' text of each polyline, then of the pieces following it.

    ezdxf writes ``repr`` of each coordinate. The drawing's coordinates are made text once
    per distinct number (by bit pattern: -0.0 is not 0.0), from one ``repr`` of their list:
    most vertices of the ATE pieces are the estimate's own, and neighbours share one.
    """
    arrays = [item.vertices for item in pending]
    arrays += [item.following.vertices for item in pending if item.following is not None]
    flat = np.concatenate([np.ascontiguousarray(a, dtype=np.float64).ravel() for a in arrays])
    distinct, index = np.unique(flat.view(np.int64), return_inverse=True)
    text = repr(distinct.view(np.float64).tolist())[1:-1].split(", ") if len(flat) else []
    every = np.array(text, dtype=object)[index.ravel()].tolist()
    bounds = np.cumsum([0, *(3 * len(a) for a in arrays)]).tolist()
    slices = iter([every[a:b] for a, b in itertools.pairwise(bounds)])
    own = [next(slices) for _ in pending]
    for item, coordinates in zip(pending, own, strict=True):  # in splice's order
        yield coordinates
        if item.following is not None:
            yield next(slices)


def _following_records(item: _Pending, coordinates: list[str]) -> str:
    """Return the records of the text-only polylines after ``item``, as ezdxf writes them.

    Every piece's records are laid into one list of strings by index (a polyline, its
    vertices, its SEQEND), each record from its constant text and its handles, so no
    Python code runs per piece or vertex.
    """
    pieces = item.following
    if pieces is None or not len(pieces):
        return ""
    counts = np.diff(pieces.offsets)
    before = pieces.offsets[:-1]  # vertices of the pieces before each
    # each piece's handle: its polyline, its SEQEND, then one per vertex, piece after piece
    handle = item.following_handle + 2 * np.arange(len(pieces)) + before
    vertex_handles = np.repeat(handle + 2 - before, counts) + np.arange(int(counts.sum()))
    colours, which = np.unique(
        np.stack([pieces.aci, pieces.true_color], axis=1), axis=0, return_inverse=True
    )
    colour_text = [f" 62\n{aci}\n420\n{rgb}\n" for aci, rgb in colours.tolist()]
    polyline_head = "  0\nPOLYLINE\n  5\n"
    polyline_middle = f"\n330\n{item.owner}\n100\nAcDbEntity\n  8\n{item.layer}\n"
    polyline_tail = "100\nAcDb3dPolyline\n 66\n1\n 10\n0.0\n 20\n0.0\n 30\n0.0\n 70\n8\n"
    seqend_tail = f"\n100\nAcDbEntity\n  8\n{item.layer}\n"
    hexes = list(map("%X".__mod__, handle.tolist()))
    seqends = list(map("%X".__mod__, (handle + 1).tolist()))
    # per piece: 5 polyline parts, its vertices' parts, 5 SEQEND parts
    head, tail = 5, 5
    size = head + _PARTS * counts + tail
    starts = np.cumsum(size) - size
    parts = np.empty(int(size.sum()), dtype=object)
    parts[starts] = polyline_head
    parts[starts + 1] = hexes
    parts[starts + 2] = polyline_middle
    parts[starts + 3] = np.array(colour_text, dtype=object)[which.ravel()]
    parts[starts + 4] = polyline_tail
    end = starts + head + _PARTS * counts
    parts[end] = "  0\nSEQEND\n  5\n"
    parts[end + 1] = seqends
    parts[end + 2] = "\n330\n"
    parts[end + 3] = hexes
    parts[end + 4] = seqend_tail
    # the vertices fill the slots between, in order
    vertex_slots = np.ones(len(parts), dtype=bool)
    vertex_slots[(starts[:, None] + np.arange(head)).ravel()] = False
    vertex_slots[(end[:, None] + np.arange(tail)).ravel()] = False
    parts[vertex_slots] = _vertex_parts(vertex_handles, item.owner, item.layer, coordinates)
    return "".join(parts.tolist())


def _vertex_records(item: _Pending, coordinates: list[str]) -> str:
    """Return the VERTEX records of one polyline as ezdxf writes them."""
    first = item.first_vertex_handle
    handles = np.arange(first, first + len(item.vertices))
    return "".join(_vertex_parts(handles, item.owner, item.layer, coordinates))


def _vertex_parts(handles: IntArray, owner: str, layer: str, coordinates: list[str]) -> list[str]:
    """Return the VERTEX records of vertices with their handles, in nine parts each.

    ``coordinates`` holds the text of each vertex's x, y and z, vertex after vertex. Built
    from C-level list operations: the record pieces are interleaved by slice assignment, so
    no Python code runs per vertex.
    """
    n = len(handles)
    middle = (
        f"\n330\n{owner}\n100\nAcDbEntity\n  8\n{layer}\n100\nAcDbVertex\n"
        "100\nAcDb3dPolylineVertex\n 10\n"
    )
    parts = [""] * (_PARTS * n)
    parts[0::9] = ["  0\nVERTEX\n  5\n"] * n
    parts[1::9] = map("%X".__mod__, handles.tolist())
    parts[2::9] = [middle] * n
    parts[3::9] = coordinates[0::3]
    parts[4::9] = ["\n 20\n"] * n
    parts[5::9] = coordinates[1::3]
    parts[6::9] = ["\n 30\n"] * n
    parts[7::9] = coordinates[2::3]
    parts[8::9] = [f"\n 70\n{_VERTEX_FLAG_3D}\n"] * n
    return parts
