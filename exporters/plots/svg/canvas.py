"""A figure of the kit: one column of axes, a legend above, a colour bar, laid out and encoded.

:class:`Figure` lays its axes out once when encoded: each margin is what the decorations on
that side take (tick labels measured with :func:`~exporters.plots.svg.metrics.text_width_pt`,
axis labels, texts the axes placed outside its box, the colour bar and its labels, the
legend above), measured again with the boxes set until they stop growing (ticks depend on
an axis' length, an equal-aspect plan widens its limits to its box). Then it writes one SVG
document: the axes' marks clipped to their boxes, the grid under them, spines, ticks and
labels over them. The PNG is that SVG rasterised by Typst (:func:`png_of_svg`), so both
formats show one drawing.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field, replace
from typing import Final

import numpy as np

from exporters.plots.svg.axes import (
    GRID_COLOUR,
    LABEL_PAD_PT,
    LABEL_SIZE_PT,
    TICK_PAD_PT,
    TICK_PT,
    TICK_SIZE_PT,
    Axes,
    LegendEntry,
)
from exporters.plots.svg.draw import (
    FONT_FAMILY,
    Box,
    Style,
    circled,
    marker_path,
    styled_path,
    svg_text,
    text_box,
    text_point,
    u,
)
from exporters.plots.svg.metrics import fit_text, text_width_pt

__all__ = ["WIDTH_IN", "ColourBar", "Figure", "png_of_svg"]

WIDTH_IN: Final = 7.0
"""Width of every report figure, inches (the kit's and matplotlib's)."""

PAD_PT: Final = 4.5
"""Space between decorations and the figure's edge, or the next plot's decorations."""
_ROUNDS: Final = 4
_LEGEND_PT: Final = 8.0
_HANDLE_PT: Final = 20.0
_ENTRY_GAP_PT: Final = 14.0
_SPINE: Final = Style(colour="#000000", width=0.8)


@dataclass
class ColourBar:
    """A colour bar of equal bins right of a plot (the ATE scale of the maps).

    Attributes:
        bounds: the bins' edges, increasing (one more than ``colours``).
        colours: each bin's colour.
        label: the bar's label, written up its right side.
        marker: a value marked across the bar with a line and a word left of it (the
            tolerance), or None.
        marker_label: that word.
    """

    bounds: list[float]
    colours: list[str]
    label: str
    marker: float | None = None
    marker_label: str = ""
    shrink: float = 0.85
    aspect: float = 20.0
    tick_labels: list[str] = field(default_factory=list)

    def position(self, value: float) -> float:
        """Where ``value`` lies up the bar, 0 (bottom) to 1: equal bins, linear in each."""
        edges = np.asarray(self.bounds, dtype=np.float64)
        return float(np.interp(value, edges, np.linspace(0.0, 1.0, edges.size)))


@dataclass
class Figure:
    """A figure of the report's width: axes in one column, decorations laid out to fit."""

    height_in: float
    width_in: float = WIDTH_IN
    axes: list[Axes] = field(default_factory=list)
    legend_from: Axes | None = None
    bar: tuple[Axes, ColourBar] | None = None
    text_boxes: dict[str, list[Box]] = field(default_factory=dict)
    """The box of every text drawn, by what drew it (``axes 0``, ``bar``, ``legend``)."""
    _legend_rows: list[list[tuple[LegendEntry, float]]] = field(default_factory=list)

    @property
    def width_pt(self) -> float:
        """The figure's width, points."""
        return 72.0 * self.width_in

    @property
    def height_pt(self) -> float:
        """The figure's height, points."""
        return 72.0 * self.height_in

    def subplots(self, rows: int = 1, *, sharex: bool = False) -> list[Axes]:
        """Add ``rows`` plots, one under the other; ``sharex``: one x axis, labelled below."""
        new = [Axes() for _ in range(rows)]
        if sharex:
            for ax in new:
                ax.shared = new
            for ax in new[:-1]:
                ax.show_xticklabels = False
        self.axes.extend(new)
        return new

    def legend_above(self, ax: Axes) -> None:
        """Show the labelled marks of ``ax`` in a legend above the plots, centred."""
        self.legend_from = ax

    def colour_bar(self, ax: Axes, bar: ColourBar) -> None:
        """Put ``bar`` right of ``ax`` (the figure's one colour bar)."""
        bar.tick_labels = [f"{b:g}".replace("-", "\u2212") for b in bar.bounds[:-1]]
        self.bar = (ax, bar)

    # -- layout ----------------------------------------------------------------------------

    def _lay_legend(self) -> float:
        """Break the legend above into rows that fit the width; return its height, points."""
        self._legend_rows = []
        entries = self.legend_from.legend_entries if self.legend_from is not None else []
        if not entries:
            return 0.0
        room = self.width_pt - 2 * PAD_PT
        label_room = room - _HANDLE_PT - 4.0
        entries = [replace(e, label=fit_text(e.label, _LEGEND_PT, label_room)) for e in entries]
        sized = [(e, _HANDLE_PT + 4.0 + text_width_pt(e.label, _LEGEND_PT)) for e in entries]
        row: list[tuple[LegendEntry, float]] = []
        for entry, width in sized:  # a handful of entries
            used = sum(w for _, w in row) + _ENTRY_GAP_PT * len(row)
            if row and used + _ENTRY_GAP_PT + width > room:
                self._legend_rows.append(row)
                row = []
            row.append((entry, width))
        self._legend_rows.append(row)
        return len(self._legend_rows) * 1.45 * _LEGEND_PT + PAD_PT

    def _bar_reach(self, ax: Axes) -> tuple[float, float]:
        """The colour bar's gap from its plot and its whole reach right of the plot, points."""
        if self.bar is None or self.bar[0] is not ax:
            return 0.0, 0.0
        bar = self.bar[1]
        gap = PAD_PT + 2.0
        if bar.marker is not None and bar.marker_label:
            gap = max(gap, text_width_pt(bar.marker_label, 7.0) + 4.0)
        width = bar.shrink * ax.box.height / bar.aspect
        labels = max((text_width_pt(t, TICK_SIZE_PT) for t in bar.tick_labels), default=0.0)
        reach = gap + width + TICK_PT + TICK_PAD_PT + labels + LABEL_PAD_PT + LABEL_SIZE_PT
        return gap, reach

    def _outside(self, ax: Axes) -> tuple[float, float, float, float]:
        """How far the axes' decorations reach left, right, below and above its box."""
        _, ylabels = ax.ticks("y")
        _, xlabels = ax.ticks("x")
        tick_w = max((text_width_pt(t, TICK_SIZE_PT) for t in ylabels), default=0.0)
        left = TICK_PT + TICK_PAD_PT + tick_w + (LABEL_PAD_PT + LABEL_SIZE_PT if ax.ylabel else 0)
        bottom = TICK_PT + TICK_PAD_PT + TICK_SIZE_PT if ax.show_xticklabels else TICK_PT
        if ax.xlabel:
            bottom += LABEL_PAD_PT + LABEL_SIZE_PT
        top = 0.5 * TICK_SIZE_PT  # the top tick label stands half above the box
        overhang = 0.5 * max((text_width_pt(t, TICK_SIZE_PT) for t in xlabels[-1:]), default=0)
        right = overhang if ax.show_xticklabels else 0.0
        right = max(right, self._bar_reach(ax)[1])
        b = ax.box
        for text in ax.texts:
            box = text_box(text, ax.point(text.x, text.y, text.coords))
            left = max(left, b.left - box.left)
            right = max(right, box.right - b.right)
            bottom = max(bottom, box.bottom - b.bottom)
            top = max(top, b.top - box.top)
        return left, right, bottom, top

    def _place(self, margins: tuple[float, ...]) -> bool:
        left, right, bottom, top, gap = margins
        n = len(self.axes)
        width = self.width_pt - left - right
        height = (self.height_pt - top - bottom - (n - 1) * gap) / n
        if width <= 10 or height <= 10:
            return False
        for r, ax in enumerate(self.axes):
            ax.box = Box(left, top + r * (height + gap), width, height)
        for ax in self.axes:
            ax.settle_limits()
        for ax in self.axes:
            ax.fit_aspect()
        return True

    def lay_out(self) -> None:
        """Set every axes' box so its decorations fit; done once, before drawing."""
        legend = self._lay_legend()
        n = len(self.axes)
        margins: tuple[float, ...] = (60.0, 20.0, 40.0, legend + 10.0, 50.0)
        self._place(margins)
        for round_ in range(_ROUNDS):
            reach = [self._outside(ax) for ax in self.axes]
            new: tuple[float, ...] = (
                max(r[0] for r in reach) + PAD_PT,
                max(r[1] for r in reach) + PAD_PT,
                reach[-1][2] + PAD_PT,
                (legend or PAD_PT) + reach[0][3],
                max((reach[i][2] + reach[i + 1][3] for i in range(n - 1)), default=0.0)
                + 2 * PAD_PT,
            )
            if all(abs(a - b) < 0.05 for a, b in zip(new, margins, strict=True)):
                break
            if round_:  # never smaller than a round before: no swinging back
                new = tuple(max(a, b) for a, b in zip(new, margins, strict=True))
            margins = new
            if not self._place(margins):
                return

    # -- drawing ---------------------------------------------------------------------------

    def svg(self) -> bytes:
        """Lay the figure out and return it as an SVG document."""
        self.lay_out()
        self.text_boxes = {}
        body: list[str] = []
        hatches: set[str] = set()
        for index, ax in enumerate(self.axes):
            body.append(self._draw_axes(ax, index))
            hatches.update(ax.hatches)
        if self.bar is not None:
            body.append(self._draw_bar(*self.bar))
        body.append(self._draw_legend_above())
        defs = "".join(
            f'<clipPath id="clip{i}"><rect x="{u(ax.box.left)}" y="{u(ax.box.top)}" '
            f'width="{u(ax.box.width)}" height="{u(ax.box.height)}"/></clipPath>'
            for i, ax in enumerate(self.axes)
        )
        defs += "".join(
            f'<pattern id="hatch-{c.lstrip("#")}" patternUnits="userSpaceOnUse" '
            f'width="{u(6)}" height="{u(6)}"><path d="M0 {u(6)}L{u(6)} 0M{u(-1)} {u(1)}L{u(1)} '
            f'{u(-1)}M{u(5)} {u(7)}L{u(7)} {u(5)}" stroke="{c}" stroke-width="{u(0.6)}"/>'
            "</pattern>"
            for c in sorted(hatches)
        )
        w, h = self.width_pt, self.height_pt
        head = (
            '<svg xmlns="http://www.w3.org/2000/svg" version="1.1" '
            f'width="{w:g}pt" height="{h:.2f}pt" viewBox="0 0 {u(w)} {u(h)}" '
            f'font-family="{FONT_FAMILY}">'
            f"<defs>{defs}</defs>"
            f'<rect width="{u(w)}" height="{u(h)}" fill="#ffffff"/>'
        )
        return (head + "".join(body) + "</svg>\n").encode()

    def _draw_axes(self, ax: Axes, index: int) -> str:
        b = ax.box
        boxes = self.text_boxes.setdefault(f"axes {index}", [])
        xs, xlabels = ax.ticks("x")
        ys, ylabels = ax.ticks("y")
        grid_x = ax.point_array(xs, "x")
        grid_y = ax.point_array(ys, "y")
        grid = "".join(
            [f"M{u(x)} {u(b.top)}V{u(b.bottom)}" for x in grid_x]
            + [f"M{u(b.left)} {u(y)}H{u(b.right)}" for y in grid_y]
        )  # a dozen ticks
        parts = [styled_path(grid, Style(colour=GRID_COLOUR, width=0.6))]
        parts.append(f'<g clip-path="url(#clip{index})">{"".join(ax.drawn_marks())}</g>')
        parts.append(styled_path(f"M{u(b.left)} {u(b.top)}V{u(b.bottom)}H{u(b.right)}", _SPINE))
        ticks = "".join(
            [f"M{u(x)} {u(b.bottom)}v{u(TICK_PT)}" for x in grid_x]
            + [f"M{u(b.left)} {u(y)}h{u(-TICK_PT)}" for y in grid_y]
        )
        parts.append(styled_path(ticks, _SPINE))
        label_y = b.bottom + TICK_PT + TICK_PAD_PT
        if ax.show_xticklabels:
            parts.extend(
                svg_text(t, x, label_y, size_pt=TICK_SIZE_PT, baseline="top", boxes=boxes)
                for x, t in zip(grid_x, xlabels, strict=True)
            )
        tick_x = b.left - TICK_PT - TICK_PAD_PT
        parts.extend(
            svg_text(
                t, tick_x, y, size_pt=TICK_SIZE_PT, anchor="end", baseline="middle", boxes=boxes
            )
            for y, t in zip(grid_y, ylabels, strict=True)
        )
        if ax.xlabel:
            below = label_y + (TICK_SIZE_PT if ax.show_xticklabels else 0.0) + LABEL_PAD_PT
            parts.append(
                svg_text(
                    ax.xlabel,
                    b.left + 0.5 * b.width,
                    below,
                    size_pt=LABEL_SIZE_PT,
                    baseline="top",
                    boxes=boxes,
                )
            )
        if ax.ylabel:
            widest = max((text_width_pt(t, TICK_SIZE_PT) for t in ylabels), default=0.0)
            x = tick_x - widest - LABEL_PAD_PT
            parts.append(
                svg_text(
                    ax.ylabel,
                    x,
                    b.top + 0.5 * b.height,
                    size_pt=LABEL_SIZE_PT,
                    rotate=True,
                    boxes=boxes,
                )
            )
        for text in ax.texts:
            at = ax.point(text.x, text.y, text.coords)
            if text.circle:
                parts.append(circled(text, at, boxes))
                continue
            parts.append(
                svg_text(
                    text.string,
                    *text_point(text, at),
                    size_pt=text.size_pt,
                    anchor=text.anchor,
                    baseline=text.baseline,
                    colour=text.colour,
                    bold=text.bold,
                    boxes=boxes,
                )
            )
        if ax.legend_inside is not None and ax.legend_entries:
            parts.append(self._draw_legend_inside(ax, boxes))
        return "".join(parts)

    def _draw_bar(self, ax: Axes, bar: ColourBar) -> str:
        gap, _ = self._bar_reach(ax)
        height = bar.shrink * ax.box.height
        width = height / bar.aspect
        left = ax.box.right + gap
        bottom = ax.box.bottom - 0.5 * (ax.box.height - height)
        n = len(bar.colours)
        boxes = self.text_boxes.setdefault("bar", [])
        parts = []
        for k, colour in enumerate(bar.colours):  # a handful of bins
            top = bottom - (k + 1) * height / n
            parts.append(
                f'<rect x="{u(left)}" y="{u(top)}" width="{u(width)}" '
                f'height="{u(height / n)}" fill="{colour}"/>'
            )
        parts.append(
            f'<rect x="{u(left)}" y="{u(bottom - height)}" width="{u(width)}" '
            f'height="{u(height)}" fill="none" stroke="#000000" stroke-width="{u(0.8)}"/>'
        )
        right = left + width
        for k, label in enumerate(bar.tick_labels):
            y = bottom - k * height / n
            parts.append(styled_path(f"M{u(right)} {u(y)}h{u(TICK_PT)}", _SPINE))
            parts.append(
                svg_text(
                    label,
                    right + TICK_PT + TICK_PAD_PT,
                    y,
                    size_pt=TICK_SIZE_PT,
                    anchor="start",
                    baseline="middle",
                    boxes=boxes,
                )
            )
        widest = max((text_width_pt(t, TICK_SIZE_PT) for t in bar.tick_labels), default=0.0)
        label_x = right + TICK_PT + TICK_PAD_PT + widest + LABEL_PAD_PT
        parts.append(
            svg_text(
                bar.label,
                label_x,
                bottom - 0.5 * height,
                size_pt=LABEL_SIZE_PT,
                baseline="top",
                rotate=True,
                boxes=boxes,
            )
        )
        if bar.marker is not None:
            y = bottom - bar.position(bar.marker) * height
            parts.append(
                styled_path(f"M{u(left)} {u(y)}H{u(right)}", Style(colour="#000000", width=1.2))
            )
            if bar.marker_label:
                parts.append(
                    svg_text(
                        bar.marker_label,
                        left - 2.0,
                        y,
                        size_pt=7.0,
                        anchor="end",
                        baseline="middle",
                        boxes=boxes,
                    )
                )
        return "".join(parts)

    def _draw_legend_above(self) -> str:
        boxes = self.text_boxes.setdefault("legend", [])
        parts = []
        line_h = 1.45 * _LEGEND_PT
        for r, row in enumerate(self._legend_rows):
            total = sum(w for _, w in row) + _ENTRY_GAP_PT * (len(row) - 1)
            x = 0.5 * (self.width_pt - total)
            y = PAD_PT + (r + 0.5) * line_h
            for entry, width in row:
                parts.append(_legend_entry(entry, x, y, boxes=boxes))
                x += width + _ENTRY_GAP_PT
        return "".join(parts)

    def _draw_legend_inside(self, ax: Axes, boxes: list[Box]) -> str:
        assert ax.legend_inside is not None  # noqa: S101  (checked by the caller)
        where, size = ax.legend_inside
        widths = [_HANDLE_PT + 4.0 + text_width_pt(e.label, size) for e in ax.legend_entries]
        line_h = 1.45 * size
        w, h = max(widths) + 2 * PAD_PT, line_h * len(widths) + PAD_PT
        corners = {
            "lower right": (ax.box.right - w - PAD_PT, ax.box.bottom - h - PAD_PT),
            "upper right": (ax.box.right - w - PAD_PT, ax.box.top + PAD_PT),
            "upper left": (ax.box.left + PAD_PT, ax.box.top + PAD_PT),
            "lower left": (ax.box.left + PAD_PT, ax.box.bottom - h - PAD_PT),
        }
        corner = where if where in corners else _emptiest(ax, corners, w, h)
        left, top = corners[corner]
        parts = [
            (
                f'<rect x="{u(left)}" y="{u(top)}" width="{u(w)}" height="{u(h)}" fill="#ffffff" '
                f'fill-opacity="0.9" stroke="#cccccc" stroke-width="{u(0.8)}" rx="{u(2)}"/>'
            )
        ]
        for k, entry in enumerate(ax.legend_entries):
            y = top + 0.5 * PAD_PT + (k + 0.5) * line_h
            parts.append(_legend_entry(entry, left + PAD_PT, y, size, boxes=boxes))
        return "".join(parts)


def _emptiest(ax: Axes, corners: dict[str, tuple[float, float]], w: float, h: float) -> str:
    """The corner whose legend box would cover the fewest drawn points (``best``)."""
    points = ax.drawn_points()
    if not len(points):
        return "upper right"

    def covered(corner: str) -> int:
        left, top = corners[corner]
        inside = (
            (points[:, 0] >= left)
            & (points[:, 0] <= left + w)
            & (points[:, 1] >= top)
            & (points[:, 1] <= top + h)
        )
        return int(inside.sum())

    return min(("upper right", "upper left", "lower left", "lower right"), key=covered)


def _legend_entry(
    entry: LegendEntry, x: float, y: float, size: float = _LEGEND_PT, *, boxes: list[Box]
) -> str:
    """One legend entry: its handle from ``x``, its text after it, centred on ``y``."""
    style = entry.style
    mid = x + 0.5 * _HANDLE_PT
    if entry.kind == "line":
        handle = styled_path(f"M{u(x)} {u(y)}h{u(_HANDLE_PT)}", style)
    elif entry.kind == "patch":
        handle = styled_path(
            f"M{u(x + 2)} {u(y - 3.5)}h{u(_HANDLE_PT - 4)}v{u(7)}h{u(4 - _HANDLE_PT)}Z", style
        )
    else:
        marker = marker_path(np.array([[mid, y]]), style.marker or "o", style.marker_pt)
        handle = styled_path(marker, style)
        if entry.kind == "errorbar":
            bar = Style(colour=style.colour, width=0.8)
            handle = styled_path(f"M{u(mid)} {u(y - 4)}v{u(8)}", bar) + handle
    text = svg_text(
        entry.label,
        x + _HANDLE_PT + 4.0,
        y,
        size_pt=size,
        anchor="start",
        baseline="middle",
        boxes=boxes,
    )
    return handle + text


def png_of_svg(svg: bytes, *, dpi: float, software: str) -> bytes:
    """Rasterise an SVG figure with Typst; return an opaque RGB PNG at ``dpi``.

    Typst draws the SVG on a page its size (the same renderer and fonts as the PDF); the
    page is re-encoded without its alpha channel (:func:`exporters.plots.png.rgb_png`).
    """
    import typst  # noqa: PLC0415  (loceval[report], as the PDF)
    from PIL import Image  # noqa: PLC0415  (matplotlib's dependency; PNG figures only)

    from exporters.plots.png import rgb_png  # noqa: PLC0415
    from exporters.plots.svg.metrics import typst_fonts  # noqa: PLC0415

    document = (
        b"#set page(width: auto, height: auto, margin: 0pt, fill: white)\n"
        b'#image(bytes(sys.inputs.figure), format: "svg")\n'
    )
    png = typst.compile(
        document,
        font_paths=typst_fonts(),
        format="png",
        ppi=dpi,
        sys_inputs={"figure": svg.decode()},
    )
    rgba = np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))
    return rgb_png(rgba, dpi=dpi, software=software)
