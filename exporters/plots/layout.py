"""A fixed layout for the report's figures: margins from the decorations' measured sizes.

matplotlib's constrained layout finds each figure's margins by walking every artist of every
axes for its tight bounding box, twice; for the report's figures that costs as much as
drawing them. These figures are simple: one grid of axes (a colour bar beside its plot at
most), tick labels, axis labels, a title, a few texts outside the axes (the CDF's threshold
labels, the excursions' notes) and a legend above the figure. :func:`lay_out` sizes the
margins and the gaps of the grid from exactly those, measuring each text with the figure's
own raster renderer (FreeType: microseconds a string), and sets the axes once: the same
boxes constrained layout gives to within a few points, at a small part of its cost.

A figure's tick labels depend on its boxes (the locator fits as many ticks as an axis'
length takes, an equal-aspect axes widens its data limits to its box): the margins are
measured again with the boxes set, until they stop growing (four rounds at most, mostly
two).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, Literal

import matplotlib as mpl

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.axis import Axis
    from matplotlib.backend_bases import RendererBase
    from matplotlib.figure import Figure
    from matplotlib.gridspec import SubplotSpec
    from matplotlib.text import Text

__all__ = ["Margins", "lay_out"]

PAD_IN: Final = 0.06
"""Space between a decoration and the figure's edge or the next axes' decorations, inches."""
_ROUNDS: Final = 4
_POINTS_PER_INCH: Final = 72.0


@dataclass
class _Outside:
    """How far an axes' decorations reach beyond its box on each side, inches."""

    left: float = 0.0
    right: float = 0.0
    bottom: float = 0.0
    top: float = 0.0


_SIZES: dict[tuple[str, object, object, float], tuple[float, float]] = {}
"""Measured text sizes, pixels, by (string, font, math, dpi): tick labels repeat from one
figure and one round to the next, and FreeType takes most of a millisecond a string."""
_SIZES_MAX: Final = 20_000


def _text_size_in(renderer: RendererBase, text: Text, string: str) -> tuple[float, float]:
    """Width and height of ``string`` set in ``text``'s font, inches (its rotation ignored)."""
    if not string:
        return 0.0, 0.0
    ismath: bool | Literal["TeX"] = "TeX" if text.get_usetex() else string.count("$") >= 2
    dpi = _dpi(renderer)
    prop = text.get_fontproperties()
    key = (string, prop, ismath, dpi)
    size = _SIZES.get(key)
    if size is None:
        width, height, _ = renderer.get_text_width_height_descent(string, prop, ismath=ismath)
        size = (float(width), float(height))
        if len(_SIZES) >= _SIZES_MAX:
            _SIZES.clear()
        _SIZES[key] = size
    lines = string.count("\n") + 1
    height_in = max(size[1] / dpi, lines * float(text.get_fontsize()) / _POINTS_PER_INCH)
    return size[0] / dpi, height_in


def _dpi(renderer: RendererBase) -> float:
    """The renderer's pixels per inch (its points_to_pixels of 72 points)."""
    pixels: float = renderer.points_to_pixels(_POINTS_PER_INCH)  # type: ignore[assignment]
    return float(pixels)


def _tick_labels(axis: Axis) -> list[str]:
    """The axis' major tick labels as they will be drawn (those within its view)."""
    lo, hi = sorted(axis.get_view_interval())
    span = hi - lo
    locs = [v for v in axis.get_majorticklocs() if lo - 1e-10 * span <= v <= hi + 1e-10 * span]
    return [s for s in axis.get_major_formatter().format_ticks(locs) if s]


def _tick_reach_in(
    axis: Axis, labels: list[str], renderer: RendererBase, *, across: bool
) -> tuple[float, float]:
    """How far the tick labels reach out from the axes, and the offset text's size, inches.

    ``across``: the labels' width counts (a y axis), else their height (an x axis).
    """
    tick = axis.get_major_ticks(1)[0]
    # The labels share one font: the longest two stand for all (the widest, whatever its
    # digits; one line high), so a dozen strings are not each set by FreeType.
    longest = sorted(labels, key=len, reverse=True)[:2]
    sizes = [_text_size_in(renderer, tick.label1, s) for s in longest]
    reach = max((w if across else h for w, h in sizes), default=0.0)
    if reach:
        pad = float(getattr(tick, "get_pad")())  # noqa: B009  (typed as returning None)
        reach += (float(tick.get_tick_padding()) + pad) / _POINTS_PER_INCH
    offset = axis.get_major_formatter().get_offset()
    return reach, _text_size_in(renderer, axis.offsetText, offset)[1]


def _end_overhang_in(
    axis: Axis, labels: list[str], renderer: RendererBase, *, across: bool
) -> float:
    """How far the labels at an axis' ends stand out along it: half a label, inches.

    ``across``: a y axis (its labels' half height counts), else an x axis (half width).
    """
    if not labels:
        return 0.0
    tick = axis.get_major_ticks(1)[0]
    ends = {labels[0], labels[-1]}
    sizes = [_text_size_in(renderer, tick.label1, s) for s in ends]
    return 0.5 * max(h if across else w for w, h in sizes)


def _label_reach_in(axis: Axis, renderer: RendererBase) -> float:
    """The axis label's thickness across the axis plus its pad, inches (0 without a label)."""
    text = axis.label.get_text()
    if not text:
        return 0.0
    _, height = _text_size_in(renderer, axis.label, text)
    return height + axis.labelpad / _POINTS_PER_INCH


def _outside(ax: Axes, renderer: RendererBase) -> _Outside:
    """Measure how far the axes' decorations reach beyond its box."""
    out = _Outside()
    x_params = ax.xaxis.get_tick_params()
    y_params = ax.yaxis.get_tick_params()
    x_labels, y_labels = _tick_labels(ax.xaxis), _tick_labels(ax.yaxis)
    x_reach, x_offset = _tick_reach_in(ax.xaxis, x_labels, renderer, across=False)
    y_reach, y_offset = _tick_reach_in(ax.yaxis, y_labels, renderer, across=True)
    x_label = _label_reach_in(ax.xaxis, renderer)
    y_label = _label_reach_in(ax.yaxis, renderer)
    bottom_ticks = x_reach if x_params.get("labelbottom") else 0.0
    top_ticks = x_reach if x_params.get("labeltop") else 0.0
    if ax.xaxis.get_label_position() == "top":
        top_ticks += max(x_label, x_offset)
    else:
        bottom_ticks += max(x_label, x_offset)
    # the end labels of an axis stand half out past the box's corners
    if x_params.get("labelbottom") or x_params.get("labeltop"):
        overhang = _end_overhang_in(ax.xaxis, x_labels, renderer, across=False)
        out.left, out.right = overhang, overhang
    if y_params.get("labelleft") or y_params.get("labelright"):
        overhang = _end_overhang_in(ax.yaxis, y_labels, renderer, across=True)
        out.bottom, out.top = overhang, overhang
    left_ticks = y_reach if y_params.get("labelleft") else 0.0
    right_ticks = y_reach if y_params.get("labelright") else 0.0
    if str(ax.yaxis.get_label_position()) == "right":
        right_ticks += y_label
    else:
        left_ticks += y_label
    if y_offset:  # the y axis' offset text sits above the axes
        top_ticks = max(top_ticks, y_offset)
    out.left, out.right = max(out.left, left_ticks), max(out.right, right_ticks)
    out.bottom, out.top = max(out.bottom, bottom_ticks), max(out.top, top_ticks)
    sides = (ax.title, getattr(ax, "_left_title", None), getattr(ax, "_right_title", None))
    titles = [t for t in sides if t is not None and t.get_text()]
    if titles:
        height = max(_text_size_in(renderer, t, t.get_text())[1] for t in titles)
        out.top += height + float(mpl.rcParams["axes.titlepad"]) / _POINTS_PER_INCH
    # Texts and notes placed outside the box (threshold labels, excursions, a colour bar's
    # tolerance mark): their extents as they stand, against the box as it stands.
    box = ax.get_window_extent(renderer)
    dpi = _dpi(renderer)
    for text in ax.texts:
        if not text.get_visible() or not text.get_text():
            continue
        extent = text.get_window_extent(renderer)
        out.left = max(out.left, (box.x0 - extent.x0) / dpi)
        out.right = max(out.right, (extent.x1 - box.x1) / dpi)
        out.bottom = max(out.bottom, (box.y0 - extent.y0) / dpi)
        out.top = max(out.top, (extent.y1 - box.y1) / dpi)
    return out


def _touches(ax: Axes) -> tuple[bool, bool, bool, bool]:
    """Whether the axes reaches the left, right, bottom and top edge of its grid cell.

    An axes of the figure's grid fills its cell; one in a cell's own grid (a plot and its
    colour bar) reaches only some edges: the others face its neighbour in the cell.
    """
    spec = ax.get_subplotspec()
    if spec is None or spec.get_topmost_subplotspec() is spec:
        return True, True, True, True  # a cell of the figure's grid: all its own
    nrows, ncols = spec.get_gridspec().get_geometry()
    rows, cols = spec.rowspan, spec.colspan
    return cols.start == 0, cols.stop == ncols, rows.stop == nrows, rows.start == 0


def _legend_height_in(fig: Figure, renderer: RendererBase) -> float:
    """How far down the legends above the figure reach (:func:`~.figure.legend_above`)."""
    dpi = _dpi(renderer)
    top = fig.bbox.y1
    reach = [(top - float(legend.get_window_extent(renderer).y0)) / dpi for legend in fig.legends]
    return max(reach, default=0.0)


def _colour_bars(fig: Figure) -> dict[Axes, tuple[Axes, float, float]]:
    """The colour bars beside one plot each: plot -> (bar, shrink, aspect).

    Those made by ``Figure.colorbar(..., ax=ax, use_gridspec=False)`` on the plot's right,
    which :func:`lay_out` places as constrained layout would: beside the plot, as tall as
    ``shrink`` of it, ``aspect`` times as tall as wide.
    """
    bars = {}
    for cax in fig.axes:
        info = getattr(cax, "_colorbar_info", None)
        if info and info["location"] == "right" and len(info["parents"]) == 1:
            bars[info["parents"][0]] = (cax, float(info["shrink"]), float(info["aspect"]))
    return bars


def _place_bars(
    fig: Figure, bars: dict[Axes, tuple[Axes, float, float]], gaps: dict[Axes, float]
) -> None:
    """Put each bar right of its plot's cell (the margin left room), centred on the plot."""
    width_in, height_in = fig.get_size_inches()
    for ax, (cax, shrink, aspect) in bars.items():
        cell = ax.get_subplotspec()
        if cell is None:
            continue
        box = cell.get_position(fig)
        ax.set_position(box)  # make_axes had narrowed it; the cell is the plot's own
        bar_h = box.height * shrink
        bar_w = bar_h * height_in / aspect / width_in
        y0 = box.y0 + 0.5 * (box.height - bar_h)
        cax.set_position((box.x1 + gaps[ax] / width_in, y0, bar_w, bar_h))


@dataclass(frozen=True)
class _Grid:
    """The figure's grid: its axes, each one's cell, the colour bars and the legend's reach."""

    axes: list[Axes]
    cells: dict[Axes, SubplotSpec]
    nrows: int
    ncols: int
    bars: dict[Axes, tuple[Axes, float, float]]
    legend_in: float


def _margins(fig: Figure, grid: _Grid, renderer: RendererBase, gaps: dict[Axes, float]) -> Margins:
    """Measure the decorations as the boxes stand; return the margins and gaps they need.

    ``gaps`` receives, per plot with a colour bar, the gap between the plot and its bar.
    """
    height_in = float(fig.get_size_inches()[1])
    left, right = [0.0] * grid.ncols, [0.0] * grid.ncols
    bottom, top = [0.0] * grid.nrows, [0.0] * grid.nrows
    for ax in grid.axes:
        cell = grid.cells[ax]
        out = _outside(ax, renderer)
        if ax in grid.bars:  # the plot's right side is its bar's: a gap, the bar, its labels
            cax, shrink, aspect = grid.bars[ax]
            bar = _outside(cax, renderer)
            gaps[ax] = max(out.right, bar.left) + PAD_IN
            out.right = gaps[ax] + ax.get_position().height * height_in * shrink / aspect
            out.right += bar.right
            out.top, out.bottom = max(out.top, bar.top), max(out.bottom, bar.bottom)
        at_left, at_right, at_bottom, at_top = _touches(ax)
        first_col, last_col = cell.colspan.start, cell.colspan.stop - 1
        first_row, last_row = cell.rowspan.start, cell.rowspan.stop - 1
        left[first_col] = max(left[first_col], out.left if at_left else 0.0)
        right[last_col] = max(right[last_col], out.right if at_right else 0.0)
        bottom[last_row] = max(bottom[last_row], out.bottom if at_bottom else 0.0)
        top[first_row] = max(top[first_row], out.top if at_top else 0.0)
    return Margins(
        left=left[0] + PAD_IN,
        right=right[-1] + PAD_IN,
        bottom=bottom[-1] + PAD_IN,
        top=top[0] + (grid.legend_in or PAD_IN),  # the legend has its own pad
        wspace=max((right[c] + left[c + 1] for c in range(grid.ncols - 1)), default=0.0)
        + 2 * PAD_IN,
        hspace=max((bottom[r] + top[r + 1] for r in range(grid.nrows - 1)), default=0.0)
        + 2 * PAD_IN,
    )


@dataclass(frozen=True)
class Margins:
    """A figure's margins and the gaps between its grid's cells, inches."""

    left: float
    right: float
    bottom: float
    top: float
    wspace: float
    hspace: float

    def at_least(self, other: Margins) -> Margins:
        """Each of these, or of ``other`` where that is larger."""
        return Margins(*(max(a, b) for a, b in zip(self.values(), other.values(), strict=True)))

    def values(self) -> tuple[float, ...]:
        """The six lengths, in the order of the fields."""
        return (self.left, self.right, self.bottom, self.top, self.wspace, self.hspace)


def _apply(fig: Figure, grid: _Grid, margins: Margins) -> bool:
    """Set the grid's margins and gaps; False when the decorations leave no room for a box."""
    width_in, height_in = (float(v) for v in fig.get_size_inches())
    cell_w = width_in - margins.left - margins.right - (grid.ncols - 1) * margins.wspace
    cell_h = height_in - margins.top - margins.bottom - (grid.nrows - 1) * margins.hspace
    cell_w, cell_h = cell_w / grid.ncols, cell_h / grid.nrows
    if cell_w <= 0 or cell_h <= 0 or not math.isfinite(cell_w + cell_h):
        return False
    fig.subplots_adjust(
        left=margins.left / width_in,
        right=1.0 - margins.right / width_in,
        bottom=margins.bottom / height_in,
        top=1.0 - margins.top / height_in,
        wspace=margins.wspace / cell_w,
        hspace=margins.hspace / cell_h,
    )
    return True


def lay_out(fig: Figure) -> None:
    """Set the figure's margins and gaps so every decoration fits, measuring text only.

    The figure's axes form one grid (made by ``Figure.subplots`` or ``add_subplot``; a
    colour bar beside a plot, see :func:`_colour_bars`); a figure without one is left as
    it is, and so is one whose decorations leave its axes no room (matplotlib's defaults).
    """
    specs = {ax: ax.get_subplotspec() for ax in fig.axes if ax.get_visible()}
    cells = {ax: spec.get_topmost_subplotspec() for ax, spec in specs.items() if spec is not None}
    if not cells:
        return
    # the raster renderer constrained layout uses (FreeType metrics; nothing is drawn)
    renderer: RendererBase = getattr(fig, "_get_renderer")()  # noqa: B009
    nrows, ncols = next(iter(cells.values())).get_gridspec().get_geometry()
    grid = _Grid(
        list(cells), cells, nrows, ncols, _colour_bars(fig), _legend_height_in(fig, renderer)
    )
    gaps: dict[Axes, float] = {}
    previous: Margins | None = None
    for _ in range(_ROUNDS):
        margins = _margins(fig, grid, renderer, gaps)
        if previous is not None:  # never smaller than a round before: no swinging back
            margins = margins.at_least(previous)
            if max(a - b for a, b in zip(margins.values(), previous.values(), strict=True)) < 1e-3:
                break
        previous = margins
        if not _apply(fig, grid, margins):
            return
        _place_bars(fig, grid.bars, gaps)
        for ax in grid.axes:
            ax.apply_aspect()
