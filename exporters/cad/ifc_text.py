"""An estimate's ATE runs in ``paths.ifc`` written as STEP text, not entity by entity.

A run is five entities: its ``IfcCartesianPointList3D``, the ``IfcIndexedPolyCurve`` through
it, and its colour (``IfcColourRgb``, ``IfcCurveStyle``, ``IfcStyledItem``). ifcopenshell
creates an entity in about 20 us per attribute, so tens of thousands of runs took seconds.
Here ifcopenshell creates the first run of each ATE bin (the *prototype*); every other run
of that bin is its prototype's five lines of STEP text with fresh entity ids and its own
coordinates, and the annotation's ``IfcShapeRepresentation`` lists every run's curve in
run order. The entities, their attributes and their order in ``Items`` are those that
creating every run with ifcopenshell gives (``tests/exporters/cad/test_ifc_text.py`` reads
both back); only the ids differ.

The prototype's lines are turned into templates with the ids as slots, outside quoted
strings (a name may hold ``#12``), so the text is ifcopenshell's own encoding of each name
and number.
"""

from __future__ import annotations

import re
import string
from dataclasses import dataclass, field
from typing import Final

import numpy as np

from exporters.errors import ExportError
from loceval.core.arrays import FloatArray, IntArray

__all__ = ["PLACEHOLDER_TEXT", "Prototype", "TextRuns", "coordinate_lists", "write_runs"]

PLACEHOLDER_TEXT: Final = "((0.,0.,0.),(0.,0.,0.))"
"""How ifcopenshell writes a point list's two-point placeholder (see ``IfcBuilder``)."""
_BODY: Final = 5
"""The template slot of a point list's coordinates (after the five ids)."""
_TOKEN: Final = re.compile(r"'(?:[^']|'')*'|#(\d+)")
"""A STEP string (quotes doubled inside) or an entity reference."""


@dataclass(frozen=True, slots=True)
class Prototype:
    """The ids of the first run of a bin, made by ifcopenshell.

    Attributes:
        ids: point list, curve, colour, curve style, styled item.
    """

    ids: tuple[int, int, int, int, int]


@dataclass(slots=True)
class TextRuns:
    """One annotation's runs: which are prototypes and which are written as text.

    Attributes:
        representation: the id of the annotation's ``IfcShapeRepresentation``.
        order: per run in order, its prototype's curve id, or None for a text run.
        prototypes: by bin index.
        bins: (T,) the bin index of each text run.
        coordinates: (V, 3) the text runs' vertices, one after another, in file coordinates.
        sizes: (T,) the text runs' vertex counts.
    """

    representation: int
    order: list[int | None] = field(default_factory=list)
    prototypes: dict[int, Prototype] = field(default_factory=dict)
    bins: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    coordinates: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    sizes: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))


def coordinate_lists(points: FloatArray, sizes: IntArray) -> list[str]:
    """Return each run's coordinates as STEP text ``(x,y,z),...`` (6 decimals), in bulk."""
    if not len(sizes):
        return []
    flat = np.ascontiguousarray(points, dtype=np.float64).reshape(-1).tolist()
    vertex = ("(%.6f,%.6f,%.6f)\n" * len(points) % tuple(flat)).split("\n")
    ends = np.cumsum(sizes).tolist()
    return [",".join(vertex[a:b]) for a, b in zip([0, *ends[:-1]], ends, strict=True)]


def write_runs(text: str, groups: list[TextRuns], first_id: int) -> tuple[str, str]:
    """Return ``text`` with each group's representation listing all its runs, and the runs.

    Args:
        text: the STEP text ifcopenshell wrote (prototypes and representations in it).
        groups: the annotations' runs.
        first_id: the first entity id free in ``text``.

    Returns:
        The text with the representations' ``Items`` completed, and the text runs' lines
        (each ending in a newline) to add to its DATA section.

    Raises:
        ExportError: a prototype or representation is not where ifcopenshell writes it.
    """
    wanted = {g.representation for g in groups}
    for group in groups:
        wanted.update(i for p in group.prototypes.values() for i in p.ids)
    lines = _lines(text, wanted)
    out: list[str] = []
    next_id = first_id
    for group in groups:
        templates = {b: _templates(p, lines) for b, p in group.prototypes.items()}
        bodies = coordinate_lists(group.coordinates, group.sizes)
        first = next_id + 5 * np.arange(len(group.bins))  # five entities per run
        out.append(_text_runs(templates, group.bins, first, bodies))
        next_id += 5 * len(group.bins)
        text = _complete_items(text, lines, group, (first + 1).tolist())
    return text, "".join(out)


def _text_runs(
    templates: dict[int, str], bins: IntArray, first: IntArray, bodies: list[str]
) -> str:
    """Return the text runs' lines: each its bin's template with its ids and coordinates.

    The templates become %-formats (their slots in one order for every bin, as one
    ifcopenshell prototype of each bin gives), so every run is filled by one ``%``
    operation over all of them; slots in another order are filled run by run.
    """
    formats = {b: _percent_format(t) for b, t in templates.items()}
    orders = {slots for _, slots in formats.values()}
    if len(orders) != 1:  # bins whose lines differ in shape: one format call per run
        return "".join(
            templates[b].format(*range(k, k + 5), body)
            for b, k, body in zip(bins.tolist(), first.tolist(), bodies, strict=True)
        )
    (slots,) = orders
    values: list[object] = [None] * (len(slots) * len(bins))
    for j, slot in enumerate(slots):  # a dozen slots: ids and the coordinates
        values[j :: len(slots)] = bodies if slot == _BODY else (first + slot).tolist()
    present = sorted(formats)
    texts = np.array([formats[b][0] for b in present], dtype=object)
    return "".join(texts[np.searchsorted(present, bins)].tolist()) % tuple(values)


def _percent_format(template: str) -> tuple[str, tuple[int, ...]]:
    """Return a ``str.format`` template as a %-format and the order of its slots."""
    pieces, slots = [], []
    for literal, slot, _, _ in string.Formatter().parse(template):
        pieces.append(literal.replace("%", "%%"))
        if slot is not None:
            pieces.append("%s")
            slots.append(int(slot))
    return "".join(pieces), tuple(slots)


def _lines(text: str, ids: set[int]) -> dict[int, str]:
    """Return the STEP lines (``#id=...;``) of ``ids`` in ``text``."""
    pattern = re.compile(r"^#(\d+)=[^\n]*$", re.MULTILINE)
    found = {int(m.group(1)): m.group(0) for m in pattern.finditer(text) if int(m.group(1)) in ids}
    missing = sorted(ids - found.keys())
    if missing:
        msg = f"the IFC text lacks the entities {missing[:5]}; please report this."
        raise ExportError(msg)
    return found


def _templates(prototype: Prototype, lines: dict[int, str]) -> str:
    """Return the prototype's five lines with its ids as slots ``{0}`` .. ``{4}``.

    Each line ends in a newline; the point list's coordinates are the slot ``{5}``.
    """
    slot = {old: k for k, old in enumerate(prototype.ids)}

    def template(line: str) -> str:
        def token(match: re.Match[str]) -> str:
            ref = match.group(1)
            if ref is not None and int(ref) in slot:
                return f"#{{{slot[int(ref)]}}}"
            return match.group(0).replace("{", "{{").replace("}", "}}")

        pieces, last = [], 0
        for match in _TOKEN.finditer(line):
            pieces.append(line[last : match.start()].replace("{", "{{").replace("}", "}}"))
            pieces.append(token(match))
            last = match.end()
        pieces.append(line[last:].replace("{", "{{").replace("}", "}}"))
        return "".join(pieces)

    head = lines[prototype.ids[0]]
    if PLACEHOLDER_TEXT not in head:
        msg = "the IFC text's point list placeholder is not where expected; please report this."
        raise ExportError(msg)
    before, after = head.split(PLACEHOLDER_TEXT, 1)
    point_list = template(before) + f"({{{_BODY}}})" + template(after)
    rest = [template(lines[i]) for i in prototype.ids[1:]]
    return "".join(f"{line}\n" for line in [point_list, *rest])


def _complete_items(
    text: str, lines: dict[int, str], group: TextRuns, text_curves: list[int]
) -> str:
    """Replace the representation's prototype ``Items`` by every run's curve, in order."""
    line = lines[group.representation]
    made = [c for c in group.order if c is not None]
    listed = "(" + ",".join(f"#{c}" for c in made) + ")"
    if line.count(listed) != 1:
        msg = "the IFC representation's items are not where expected; please report this."
        raise ExportError(msg)
    curves = iter(text_curves)
    every = [c if c is not None else next(curves) for c in group.order]
    full = line.replace(listed, "(" + ",".join(f"#{c}" for c in every) + ")")
    return text.replace(line, full, 1)
