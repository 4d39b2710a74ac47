"""One plot of a figure: the marks it draws in data coordinates, its limits and its labels.

An :class:`Axes` records what it draws (lines, bands, markers, spans, coloured segments,
texts) with their data; nothing is placed until the figure's layout has given the axes its
box (:mod:`exporters.plots.svg.canvas`), then :meth:`Axes.draw` writes the SVG. Every mark
is a handful of ``<path>`` elements whatever the number of vertices: a line's vertices are
formatted by NumPy (:func:`exporters.plots.svg.draw.path_data`), never one element a point.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final, Literal

import numpy as np

from exporters.plots.svg.draw import (
    Box,
    Coord,
    Mark,
    Style,
    Text,
    marker_path,
    path_data,
    polygon_data,
    segment_data,
    styled_path,
)
from exporters.plots.svg.metrics import text_width_pt
from exporters.plots.svg.ticks import format_ticks, nice_ticks, padded_limits
from loceval.core.arrays import FloatArray, IntArray

__all__ = ["Axes", "LegendEntry"]

GRID_COLOUR: Final = "#e0e0e0"
TICK_PT: Final = 3.5
TICK_PAD_PT: Final = 3.5
LABEL_PAD_PT: Final = 4.0
TICK_SIZE_PT: Final = 9.0
LABEL_SIZE_PT: Final = 9.5


@dataclass(frozen=True)
class LegendEntry:
    """What the legend shows for one labelled mark: a line, a marker or a patch."""

    label: str
    kind: Literal["line", "marker", "patch", "errorbar"]
    style: Style


@dataclass
class _Limits:
    """One axis' data range (from the marks), and any limit set by hand."""

    lo: float = math.inf
    hi: float = -math.inf
    fixed_lo: float | None = None
    fixed_hi: float | None = None
    min_hi: float | None = None

    def add(self, values: FloatArray) -> None:
        finite = values[np.isfinite(values)]
        if finite.size:
            self.lo = min(self.lo, float(finite.min()))
            self.hi = max(self.hi, float(finite.max()))

    def view(self) -> tuple[float, float]:
        """The axis' limits: the data padded by 5 %, or those set."""
        lo, hi = padded_limits(self.lo, self.hi)
        if self.fixed_lo is not None:
            lo = self.fixed_lo
        if self.fixed_hi is not None:
            hi = self.fixed_hi
        if self.min_hi is not None:
            hi = max(hi, self.min_hi)
        if hi <= lo:
            hi = lo + 1.0
        return lo, hi


@dataclass
class Axes:
    """A plot's marks and axes; placed and drawn by its figure."""

    xlabel: str = ""
    ylabel: str = ""
    equal: bool = False
    show_xticklabels: bool = True
    marks: list[tuple[float, int, Mark]] = field(default_factory=list)
    texts: list[Text] = field(default_factory=list)
    legend_entries: list[LegendEntry] = field(default_factory=list)
    legend_inside: tuple[str, float] | None = None
    x: _Limits = field(default_factory=_Limits)
    y: _Limits = field(default_factory=_Limits)
    view_x: tuple[float, float] = (0.0, 1.0)
    view_y: tuple[float, float] = (0.0, 1.0)
    box: Box = field(default_factory=lambda: Box(0.0, 0.0, 1.0, 1.0))
    shared: list[Axes] = field(default_factory=list)
    drawn_xy: list[tuple[FloatArray, FloatArray]] = field(default_factory=list)
    hatches: set[str] = field(default_factory=set)

    # -- what is drawn ---------------------------------------------------------------------

    def _add(self, z: float, mark: Mark, label: str | None, entry: LegendEntry | None) -> None:
        self.marks.append((z, len(self.marks), mark))
        if label and entry is not None:
            self.legend_entries.append(entry)

    def line(
        self,
        x: FloatArray,
        y: FloatArray,
        style: Style,
        *,
        label: str | None = None,
        z: float = 2.0,
        autolim: bool = True,
    ) -> None:
        """A line through the points; a NaN in ``x`` or ``y`` breaks it."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        if autolim:
            ok = np.isfinite(x) & np.isfinite(y)
            self.x.add(x[ok])
            self.y.add(y[ok])
        self.drawn_xy.append((x, y))
        self._add(
            z,
            lambda: styled_path(path_data(self._points(x, y)), style),
            label,
            LegendEntry(label or "", "line", style),
        )

    def step(self, x: FloatArray, y: FloatArray, style: Style, *, label: str | None = None) -> None:
        """A step line: each value held until the next ``x`` (matplotlib's ``where="post"``)."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        if x.size >= 2:
            x = np.repeat(x, 2)[1:]
            y = np.repeat(y, 2)[:-1]
        self.line(x, y, style, label=label)

    def band(
        self, x: FloatArray, lo: FloatArray, hi: FloatArray, style: Style, *, z: float = 1.5
    ) -> None:
        """A filled band between ``lo`` and ``hi``; a NaN row breaks it."""
        x = np.asarray(x, dtype=np.float64)
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        ok = np.isfinite(x) & np.isfinite(lo) & np.isfinite(hi)
        self.x.add(x[ok])
        self.y.add(np.concatenate([lo[ok], hi[ok]]))
        self._add(
            z,
            lambda: styled_path(polygon_data(self._points(x, hi), self._points(x, lo), ok), style),
            None,
            None,
        )

    def markers(
        self,
        x: FloatArray,
        y: FloatArray,
        style: Style,
        *,
        shape: Literal["o", "P"] = "o",
        size_pt: float = 4.0,
        label: str | None = None,
        z: float = 2.5,
    ) -> None:
        """Markers at the points (``o`` a circle, ``P`` a filled plus), ``size_pt`` across."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        ok = np.isfinite(x) & np.isfinite(y)
        self.x.add(x[ok])
        self.y.add(y[ok])
        self.drawn_xy.append((x, y))
        marker = Style(
            colour=style.colour,
            width=style.width,
            face=style.face or style.colour,
            alpha=style.alpha,
            marker=shape,
            marker_pt=size_pt,
        )
        self._add(
            z,
            lambda: styled_path(marker_path(self._points(x[ok], y[ok]), shape, size_pt), marker),
            label,
            LegendEntry(label or "", "marker", marker),
        )

    def errorbars(
        self, x: FloatArray, y: FloatArray, err: FloatArray, style: Style, *, label: str | None
    ) -> None:
        """Points with vertical bars of ``y ± err`` (circles ``style.face`` filled)."""
        x, y, err = (np.asarray(v, dtype=np.float64) for v in (x, y, err))
        ok = np.isfinite(x) & np.isfinite(y)
        bar = np.where(np.isfinite(err), err, 0.0)
        self.x.add(x[ok])
        self.y.add(np.concatenate([(y - bar)[ok], (y + bar)[ok]]))
        x, y, bar = x[ok], y[ok], bar[ok]
        ends = np.stack([np.stack([x, y - bar], 1), np.stack([x, y + bar], 1)], axis=1)
        line = Style(colour=style.colour, width=0.8)
        self._add(2.4, lambda: styled_path(segment_data(self._segments(ends)), line), None, None)
        self.markers(x, y, style, size_pt=4.5, label=label)
        if label:
            self.legend_entries[-1] = LegendEntry(label, "errorbar", self.legend_entries[-1].style)

    def segments(
        self,
        segments: FloatArray,
        classes: IntArray,
        colours: Sequence[str],
        *,
        width: float,
        z: float = 3.0,
        group: str | None = None,
        autolim: bool = True,
    ) -> None:
        """Line segments (K, 2, 2), each in ``colours[classes[k]]``: one path per colour."""
        segments = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
        if autolim and len(segments):
            self.x.add(segments[:, :, 0].ravel())
            self.y.add(segments[:, :, 1].ravel())

        def draw() -> str:
            parts = []
            for c, colour in enumerate(colours):
                picked = segments[classes == c]
                if len(picked):
                    style = Style(colour=colour, width=width, cap="round")
                    parts.append(styled_path(segment_data(self._segments(picked)), style))
            body = "".join(parts)
            return f'<g id="{group}">{body}</g>' if group else body

        self._add(z, draw, None, None)

    def hline(self, y: float, style: Style, *, label: str | None = None, z: float = 2.2) -> None:
        """A horizontal line across the plot at ``y`` (its value counts in the limits)."""
        self.y.add(np.array([y]))
        self._add(
            z,
            lambda: styled_path(
                segment_data(self._to_pt_segments([[self.view_x[0], y], [self.view_x[1], y]])),
                style,
            ),
            label,
            LegendEntry(label or "", "line", style),
        )

    def vline(self, x: float, style: Style, *, z: float = 1.8) -> None:
        """A vertical line from the bottom to the top of the plot at ``x`` (in the limits)."""
        self.x.add(np.array([x]))
        self._add(
            z,
            lambda: styled_path(
                segment_data(self._to_pt_segments([[x, self.view_y[0]], [x, self.view_y[1]]])),
                style,
            ),
            None,
            None,
        )

    def xspans(
        self,
        starts: FloatArray,
        ends: FloatArray,
        style: Style,
        *,
        label: str | None = None,
        z: float = 1.0,
    ) -> None:
        """Bands from ``starts`` to ``ends`` over the plot's whole height."""
        starts = np.asarray(starts, dtype=np.float64)
        ends = np.asarray(ends, dtype=np.float64)
        if style.hatch:
            self.hatches.add(style.hatch)

        def draw() -> str:
            lo, hi = self.view_y
            n = starts.size
            top = self._points(np.concatenate([starts, ends]), np.full(2 * n, hi))
            bottom = self._points(np.concatenate([starts, ends]), np.full(2 * n, lo))
            corners = np.stack([bottom[:n], top[:n], top[n:], bottom[n:]], axis=1)
            return styled_path(segment_data(corners, closed=True), style)

        self._add(z, draw, label, LegendEntry(label or "", "patch", style))

    def text(
        self,
        x: float,
        y: float,
        string: str,
        *,
        coords: tuple[Coord, Coord] = ("data", "data"),
        offset_pt: tuple[float, float] = (0.0, 0.0),
        anchor: Literal["start", "middle", "end"] = "middle",
        baseline: Literal["bottom", "middle", "top"] = "bottom",
        size_pt: float = 7.0,
        colour: str = "#000000",
        bold: bool = False,
        circle: str | None = None,
    ) -> None:
        """A text at a point of data or axes coordinates (``axes``: 0 to 1 across the box).

        ``circle``: the colour of a ring drawn round the text, with a leader line from the
        point to it (a numbered marker), else None.
        """
        self.texts.append(
            Text(x, y, string, coords, offset_pt, anchor, baseline, size_pt, colour, bold, circle)
        )

    def legend(self, where: Literal["lower right", "best"], size_pt: float = 8.0) -> None:
        """Put the labelled marks' legend inside the plot (``best``: the emptiest corner)."""
        self.legend_inside = (where, size_pt)

    # -- limits ----------------------------------------------------------------------------

    def set_xlim(self, lo: float | None = None, hi: float | None = None) -> None:
        """Fix the x axis' lower or upper limit (the other stays automatic)."""
        self.x.fixed_lo, self.x.fixed_hi = lo, hi

    def set_ylim(
        self, lo: float | None = None, hi: float | None = None, *, at_least: float | None = None
    ) -> None:
        """Fix the y axis' limits; ``at_least``: the upper limit is at least this."""
        self.y.fixed_lo, self.y.fixed_hi, self.y.min_hi = lo, hi, at_least

    def settle_limits(self) -> None:
        """Set the view from the data (x shared with the axes of :attr:`shared`)."""
        self.view_x = self.x.view()
        if self.shared:
            views = [a.x.view() for a in self.shared]
            self.view_x = (min(v[0] for v in views), max(v[1] for v in views))
        self.view_y = self.y.view()

    def fit_aspect(self) -> None:
        """Widen one axis' view so a metre is as long across as up (an equal-aspect plan)."""
        if not self.equal:
            return
        (x0, x1), (y0, y1) = self.view_x, self.view_y
        per_pt = max((x1 - x0) / self.box.width, (y1 - y0) / self.box.height)
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        half_x, half_y = 0.5 * per_pt * self.box.width, 0.5 * per_pt * self.box.height
        self.view_x, self.view_y = (cx - half_x, cx + half_x), (cy - half_y, cy + half_y)

    def ticks(self, axis: Literal["x", "y"]) -> tuple[FloatArray, list[str]]:
        """The axis' tick values within the view and their labels, for the box as it is."""
        lo, hi = self.view_x if axis == "x" else self.view_y
        # as many intervals as fit three label heights apart across (two up), 9 at most
        space = self.box.width / 3.0 if axis == "x" else self.box.height / 2.0
        intervals = int(np.clip(space // TICK_SIZE_PT, 1, 9))
        while True:  # fewer ticks while long labels (site coordinates) would touch
            values, step = nice_ticks(lo, hi, intervals + 1)
            labels = format_ticks(values, step)
            if axis == "y" or intervals == 1:
                return values, labels
            widest = max((text_width_pt(t, TICK_SIZE_PT) for t in labels), default=0.0)
            if (widest + TICK_SIZE_PT) * len(labels) <= self.box.width:
                return values, labels
            intervals -= 1

    # -- coordinates -----------------------------------------------------------------------

    def _points(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """Data coordinates to figure points (x right, y down), NaN kept."""
        (x0, x1), (y0, y1) = self.view_x, self.view_y
        b = self.box
        px = b.left + (np.asarray(x, dtype=np.float64) - x0) * (b.width / (x1 - x0))
        py = b.bottom - (np.asarray(y, dtype=np.float64) - y0) * (b.height / (y1 - y0))
        return np.stack([px, py], axis=-1)

    def _segments(self, segments: FloatArray) -> FloatArray:
        return self._points(segments[..., 0], segments[..., 1])

    def _to_pt_segments(self, ends: list[list[float]]) -> FloatArray:
        return self._segments(np.asarray([ends], dtype=np.float64))

    def point(self, x: float, y: float, coords: tuple[Coord, Coord]) -> tuple[float, float]:
        """One point of data or axes coordinates, in figure points."""
        b = self.box
        (x0, x1), (y0, y1) = self.view_x, self.view_y
        px = b.left + (x if coords[0] == "axes" else (x - x0) / (x1 - x0)) * b.width
        py = b.bottom - (y if coords[1] == "axes" else (y - y0) / (y1 - y0)) * b.height
        return px, py

    def point_array(self, values: FloatArray, axis: Literal["x", "y"]) -> FloatArray:
        """Positions of data values along one axis, figure points."""
        b = self.box
        lo, hi = self.view_x if axis == "x" else self.view_y
        share = (np.asarray(values, dtype=np.float64) - lo) / (hi - lo)
        out: FloatArray = b.left + share * b.width if axis == "x" else b.bottom - share * b.height
        return out

    def drawn_points(self) -> FloatArray:
        """Every point of the lines and markers drawn, figure points (N, 2)."""
        if not self.drawn_xy:
            return np.zeros((0, 2))
        points = np.concatenate([self._points(x, y) for x, y in self.drawn_xy])
        out: FloatArray = points[np.isfinite(points).all(axis=1)]
        return out

    def drawn_marks(self) -> list[str]:
        """The marks' SVG, in order of depth (then of drawing)."""
        return [mark() for _, _, mark in sorted(self.marks, key=lambda m: (m[0], m[1]))]
