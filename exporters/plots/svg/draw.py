"""SVG primitives of the figure kit: styles, boxes, texts and path data built by NumPy.

Coordinates are figure points (1/72 in, y down) while the figure is laid out; the SVG's user
unit is a hundredth of a point (the figure's ``viewBox`` is 100 times its size in points),
so every coordinate is written as an integer: exact to 1/7200 in, far below what a screen
or printer shows, and formatted for a whole array at once.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Literal, TypeAlias

import numpy as np

from exporters.plots.svg.metrics import text_width_pt
from loceval.core.arrays import BoolArray, FloatArray

__all__ = [
    "FONT_FAMILY",
    "UNIT",
    "Box",
    "Coord",
    "Mark",
    "Style",
    "Text",
    "marker_path",
    "path_data",
    "polygon_data",
    "segment_data",
    "styled_path",
    "svg_text",
    "text_box",
    "u",
]

UNIT: Final = 100
"""SVG user units per point."""
FONT_FAMILY: Final = "'DejaVu Sans', 'Bitstream Vera Sans', Verdana, sans-serif"
"""The figures' font: DejaVu Sans (the PDF's own), then the fonts that set it alike."""
_ASCENT: Final = 0.76
_DESCENT: Final = 0.24
"""DejaVu Sans' ascent and descent as shares of the font size (the box a line takes)."""

Coord: TypeAlias = Literal["data", "axes"]
"""A text's coordinates along one axis: data values, or 0 to 1 across the plot."""
Mark: TypeAlias = Callable[[], str]
"""A recorded mark: returns its SVG once the axes has been placed."""


def escape(text: str) -> str:
    """The text with XML's three special characters escaped."""
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def u(value: float) -> int:
    """A length or coordinate in points as SVG user units (an integer)."""
    return round(value * UNIT)


@dataclass(frozen=True)
class Box:
    """A rectangle of the figure, points from its top-left corner."""

    left: float
    top: float
    width: float
    height: float

    @property
    def right(self) -> float:
        """The right edge, points."""
        return self.left + self.width

    @property
    def bottom(self) -> float:
        """The bottom edge, points."""
        return self.top + self.height


@dataclass(frozen=True)
class Style:
    """How a mark is stroked and filled.

    Attributes:
        colour: the stroke (a line, a marker's edge), or None for none.
        width: the stroke's width, points.
        face: the fill (markers, bands, spans), or None for none.
        alpha: the opacity of the fill and of the stroke.
        dash: ``"dashed"``, ``"dotted"`` or None (solid).
        cap: the line ends: ``"butt"`` or ``"round"``.
        hatch: a colour for diagonal hatching over the fill, or None.
        marker: the shape a legend shows for a marker (``o``, ``P``).
        marker_pt: its size across, points.
    """

    colour: str | None = "#000000"
    width: float = 1.0
    face: str | None = None
    alpha: float = 1.0
    dash: Literal["dashed", "dotted"] | None = None
    cap: Literal["butt", "round"] = "butt"
    hatch: str | None = None
    marker: str | None = None
    marker_pt: float = 0.0


@dataclass(frozen=True)
class Text:
    """A text an axes writes, where and how (see :meth:`~.axes.Axes.text`)."""

    x: float
    y: float
    string: str
    coords: tuple[Coord, Coord]
    offset_pt: tuple[float, float]
    anchor: Literal["start", "middle", "end"]
    baseline: Literal["bottom", "middle", "top"]
    size_pt: float
    colour: str
    bold: bool
    circle: str | None


def _dash(style: Style) -> str:
    if style.dash == "dashed":
        return f' stroke-dasharray="{u(3.7 * style.width)} {u(1.6 * style.width)}"'
    if style.dash == "dotted":
        return f' stroke-dasharray="{u(1.0 * style.width)} {u(1.65 * style.width)}"'
    return ""


def styled_path(data: str, style: Style) -> str:
    """Return a ``<path>`` with ``data`` stroked and filled as ``style`` says ("" if empty)."""
    if not data:
        return ""
    attrs = [f'd="{data}"']
    attrs.append(f'fill="{style.face}"' if style.face else 'fill="none"')
    if style.face and style.alpha < 1:
        attrs.append(f'fill-opacity="{style.alpha:.3g}"')
    if style.colour and style.width > 0:
        attrs.append(f'stroke="{style.colour}" stroke-width="{u(style.width)}"')
        attrs.append(f'stroke-linejoin="round" stroke-linecap="{style.cap}"{_dash(style)}')
        if style.alpha < 1:
            attrs.append(f'stroke-opacity="{style.alpha:.3g}"')
    path = "<path " + " ".join(attrs) + "/>"
    if style.hatch:
        path += f'<path d="{data}" fill="url(#hatch-{style.hatch.lstrip("#")})" stroke="none"/>'
    return path


def _joined(points: FloatArray, starts: BoolArray, closed: BoolArray | None = None) -> str:
    """Path data through ``points`` (N, 2): ``M`` where ``starts``, else an implicit line.

    The coordinates are formatted for the whole array at once (``map(str, ...)`` over the
    integers); only the few pieces' first points get their command letters one by one.
    """
    if not len(points):
        return ""
    tokens = list(map(str, np.rint(points * UNIT).astype(np.int64).ravel().tolist()))
    first = np.flatnonzero(starts)
    second = first + 1
    second = second[second < len(points)]
    second = second[~starts[second]]
    for i in first.tolist():  # one per piece of the line (a break, a segment)
        tokens[2 * i] = "M" + tokens[2 * i]
    for i in second.tolist():
        tokens[2 * i] = "L" + tokens[2 * i]
    if closed is not None:
        for i in np.flatnonzero(closed).tolist():
            tokens[2 * i + 1] += "Z"
    return " ".join(tokens)


def path_data(points: FloatArray) -> str:
    """Path data of a line through ``points`` (N, 2); a NaN point breaks it.

    A lone point between two breaks draws nothing, as a line of one point shows nothing.
    """
    ok: BoolArray = np.asarray(np.isfinite(points).all(axis=1))
    before = np.zeros_like(ok)
    before[1:] = ok[:-1]
    after = np.zeros_like(ok)
    after[:-1] = ok[1:]
    starts, ends = ok & ~before, ok & ~after
    keep = ok & ~(starts & ends)
    return _joined(points[keep], starts[keep])


def polygon_data(upper: FloatArray, lower: FloatArray, ok: BoolArray) -> str:
    """Path data of the closed bands between ``upper`` and ``lower`` over each run of ``ok``."""
    index = np.flatnonzero(ok)
    if not index.size:
        return ""
    runs = np.split(index, np.flatnonzero(np.diff(index) > 1) + 1)  # a few runs (the gaps)
    rings = [np.concatenate([upper[r], lower[r][::-1]]) for r in runs if r.size >= 2]
    if not rings:
        return ""
    points = np.concatenate(rings)
    starts = np.zeros(len(points), dtype=bool)
    lengths = np.array([len(r) for r in rings])
    first = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    starts[first] = True
    closed = np.zeros(len(points), dtype=bool)
    closed[first + lengths - 1] = True
    return _joined(points, starts, closed)


def segment_data(segments: FloatArray, *, closed: bool = False) -> str:
    """Path data of polylines (K, M, 2) (segments when M is 2); one joins the next it meets.

    A segment starting where the one before it ended continues that line, so a path of
    consecutive segments is written as one line, not as K moves.
    """
    segments = np.asarray(segments, dtype=np.float64)
    k, m = segments.shape[:2]
    if not k:
        return ""
    points = segments.reshape(-1, 2)
    starts = np.zeros(k * m, dtype=bool)
    starts[::m] = True
    if m == 2 and not closed:  # drop the repeated point where a segment goes on
        rounded = np.rint(segments * UNIT)
        goes_on = np.zeros(k, dtype=bool)
        goes_on[1:] = (rounded[1:, 0] == rounded[:-1, 1]).all(axis=1)
        keep = np.ones(k * m, dtype=bool)
        keep[0::2][goes_on] = False
        return _joined(points[keep], starts[keep])
    ends = np.zeros(k * m, dtype=bool)
    ends[m - 1 :: m] = closed
    return _joined(points, starts, ends if closed else None)


def marker_path(points: FloatArray, shape: str, size_pt: float) -> str:
    """Path data of a marker (``o`` a circle, ``P`` a filled plus) at each point."""
    if not len(points):
        return ""
    r = 0.5 * size_pt
    if shape == "P":  # a plus of arms a third of the size wide
        a, b = r, r / 3.0
        outline = np.array(
            [
                [-b, -a],
                [b, -a],
                [b, -b],
                [a, -b],
                [a, b],
                [b, b],
                [b, a],
                [-b, a],
                [-b, b],
                [-a, b],
                [-a, -b],
                [-b, -b],
            ]
        )
        rings = points[:, None, :] + outline[None, :, :]
        return segment_data(rings, closed=True)
    xy = np.rint(points * UNIT).astype(np.int64)
    ru = u(r)
    xy[:, 0] -= ru  # each circle starts at its left end
    arcs = f"a{ru} {ru} 0 1 0 {2 * ru} 0a{ru} {ru} 0 1 0 {-2 * ru} 0Z"
    return (f"M{{}} {{}}{arcs}" * len(xy)).format(*xy.ravel().tolist())


def _extent(
    string: str, size_pt: float, anchor: str, baseline: str, *, bold: bool
) -> tuple[float, float, float]:
    """How a line of text lies about its anchor point, points.

    Returns:
        ``(width, along, across)``: its width (DejaVu's advance widths); where it starts
        along its line from the point (``anchor``: the point is its start, middle or end);
        where its baseline lies across from the point (``baseline``: the point is the
        bottom, middle or top edge of its box, ascent plus descent high).
    """
    width = text_width_pt(string, size_pt, bold=bold)
    along = {"start": 0.0, "middle": -0.5, "end": -1.0}[anchor] * width
    across = {"bottom": -_DESCENT, "middle": 0.5 - _DESCENT, "top": _ASCENT}[baseline] * size_pt
    return width, along, across


def text_point(text: Text, at: tuple[float, float]) -> tuple[float, float]:
    """Where an axes' text is set: its point ``at`` (points) moved by its offset (up is +)."""
    return at[0] + text.offset_pt[0], at[1] - text.offset_pt[1]


def text_box(text: Text, at: tuple[float, float]) -> Box:
    """The box a text takes when its anchor point is ``at`` (points), as the SVG sets it."""
    x, y = text_point(text, at)
    width, along, across = _extent(
        text.string, text.size_pt, text.anchor, text.baseline, bold=text.bold
    )
    height = (_ASCENT + _DESCENT) * text.size_pt
    if text.circle:
        side = max(width, height) + 0.5 * text.size_pt  # a quarter of the size's pad round
        return Box(x - 0.5 * side, y - 0.5 * side, side, side)
    return Box(x + along, y + across - _ASCENT * text.size_pt, width, height)


def svg_text(
    string: str,
    x: float,
    y: float,
    *,
    size_pt: float,
    anchor: str = "middle",
    baseline: str = "bottom",
    colour: str = "#000000",
    bold: bool = False,
    rotate: bool = False,
    boxes: list[Box] | None = None,
) -> str:
    """One line of text at ``(x, y)``: ``anchor`` along it, ``baseline`` which edge across.

    ``rotate``: turned 90° to read upwards; its bottom edge then faces right, so
    ``baseline="bottom"`` puts its right edge at ``x``, ``"top"`` its left edge. ``boxes``
    receives the box the text takes.
    """
    width, along, across = _extent(string, size_pt, anchor, baseline, bold=bold)
    thick = (_ASCENT + _DESCENT) * size_pt
    if rotate:  # the text runs up from y; the baseline is a vertical line at x_pt
        x_pt, y_pt = x + across, y
        transform = f' transform="rotate(-90 {u(x_pt)} {u(y_pt)})"'
        box = Box(x_pt - _ASCENT * size_pt, y - along - width, thick, width)
    else:
        x_pt, y_pt = x, y + across
        transform = ""
        box = Box(x + along, y_pt - _ASCENT * size_pt, width, thick)
    if boxes is not None:
        boxes.append(box)
    weight = ' font-weight="bold"' if bold else ""
    fill = "" if colour == "#000000" else f' fill="{colour}"'
    return (
        f'<text x="{u(x_pt)}" y="{u(y_pt)}" font-size="{u(size_pt)}" '
        f'text-anchor="{anchor}"{weight}{fill}{transform}>{escape(string)}</text>'
    )


def circled(text: Text, at: tuple[float, float], boxes: list[Box] | None = None) -> str:
    """A numbered marker: a leader from the point to a white ring round the text."""
    box = text_box(text, at)
    if boxes is not None:
        boxes.append(box)
    cx, cy = box.left + 0.5 * box.width, box.top + 0.5 * box.height
    r = 0.5 * box.width
    leader_len = math.hypot(cx - at[0], cy - at[1])
    share = max(leader_len - r, 0.0) / leader_len if leader_len else 0.0
    end = (at[0] + (cx - at[0]) * share, at[1] + (cy - at[1]) * share)
    colour = text.circle or "#000000"
    return (
        f'<path d="M{u(at[0])} {u(at[1])}L{u(end[0])} {u(end[1])}" stroke="{colour}" '
        f'stroke-width="{u(0.8)}"/>'
        f'<circle cx="{u(cx)}" cy="{u(cy)}" r="{u(r)}" fill="#ffffff" '
        f'stroke="{colour}" stroke-width="{u(1.0)}"/>'
        + svg_text(text.string, cx, cy, size_pt=text.size_pt, baseline="middle", bold=text.bold)
    )
