"""The matplotlib figures of the plots not drawn by the kit: built, styled, laid out, encoded.

The trials' box plots, the ranging plots, a robot's map, the checkpoint plan and the summary
report's plots are matplotlib figures built directly (no pyplot, no backend switch, no
rcParams changes, no display). This module is imported only when one of them is drawn, so a
report without them never imports matplotlib (:mod:`exporters.plots.figure`).
"""

from __future__ import annotations

import contextlib
import io
import operator
import re
from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.layout_engine import PlaceHolderLayoutEngine
from matplotlib.lines import Line2D

from exporters.plots.layout import lay_out
from exporters.plots.png import rgb_png
from exporters.plots.svg.canvas import WIDTH_IN

__all__ = ["encode_figure", "keep_every_vertex", "legend_above", "new_figure", "style_axes"]


_SVG_NUMBER = re.compile(rb"(\d\.\d\d)\d+")
_SVG_PATH_DATA = re.compile(rb' d="[^"]*"')


def _svg(fig: Figure, dpi: float) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="svg", dpi=dpi, metadata={"Date": None, "Creator": "loceval"})
    # Path coordinates are points (1/72 in); matplotlib writes six decimals. Two (1/7200 in)
    # are far below what any screen or printer shows and make the SVG a third smaller.
    return _SVG_PATH_DATA.sub(_two_decimals, buf.getvalue())


_FIRST_GROUP = operator.itemgetter(1)
"""A match's first group, as a callable ``re.sub`` calls without a template to expand."""


def _two_decimals(path_data: re.Match[bytes]) -> bytes:
    """Return an SVG path's ``d`` attribute with its numbers cut to two decimals."""
    return _SVG_NUMBER.sub(_FIRST_GROUP, path_data.group(0))


def _png(fig: Figure, dpi: float) -> bytes:
    """Encode the figure as an opaque RGB PNG at ``dpi``.

    The figure is drawn into an RGBA buffer and encoded without its alpha channel
    (:func:`exporters.plots.png.rgb_png`): every figure has an opaque white background,
    so the picture is the same, and WeasyPrint would otherwise split the alpha off into a
    soft mask, decoding and encoding each image once more.
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="rgba", dpi=dpi)
    width = int(fig.get_figwidth() * dpi)  # matplotlib's canvas size: truncated
    rgba = np.frombuffer(buf.getbuffer(), dtype=np.uint8).reshape(-1, width, 4)
    return rgb_png(rgba, dpi=dpi, software="loceval")


def encode_figure(
    fig: Figure, formats: Sequence[str], *, png_dpi: float, svg_dpi: float
) -> tuple[bytes | None, bytes | None]:
    """Encode a finished figure as SVG and PNG (laid out once, drawn once per format)."""
    svg = png = None
    _lay_out_once(fig)
    if "svg" in formats:
        svg = _svg(fig, svg_dpi)
    if "png" in formats:
        png = _png(fig, png_dpi)
    return svg, png


def _lay_out_once(fig: Figure) -> None:
    """Lay the figure out once, with the fixed layout (:func:`exporters.plots.layout.lay_out`).

    The figure has no layout engine (:func:`new_figure`), so every format is then drawn
    once, at the same positions: a figure's SVG and PNG show one layout. A figure made with
    an engine of its own (or a matplotlibrc asking for one) has it run once and removed.
    """
    engine = fig.get_layout_engine()
    if engine is not None and not isinstance(engine, PlaceHolderLayoutEngine):
        if fig.axes:
            with contextlib.suppress(ValueError):  # as Figure.draw: axes too small to lay out
                engine.execute(fig)
        fig.set_layout_engine("none")
        return
    lay_out(fig)


def keep_every_vertex(lines: Sequence[Line2D]) -> None:
    """Switch off matplotlib's path simplification for these lines.

    A line is already decimated to ``max_points`` vertices; simplification would further
    drop vertices it finds collinear, so a 1.5 Hz AMCL path of 129 poses showed 108.
    """
    for line in lines:
        line.get_path().should_simplify = False


def new_figure(height_in: float) -> Figure:
    """Return an empty figure of the report's width, ``height_in`` inches high.

    It has no layout engine: :func:`encode_plot` lays it out once, with the fixed layout of
    :mod:`exporters.plots.layout` (constrained layout cost as much as the drawing).
    """
    fig = Figure(figsize=(WIDTH_IN, height_in), dpi=150)
    fig.set_layout_engine("none")  # whatever a matplotlibrc asks for
    return fig


def style_axes(ax: Axes) -> None:
    """Give the axes the report's light grid and no top or right spine."""
    ax.grid(visible=True, color="#e0e0e0", linewidth=0.6)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def legend_above(fig: Figure, ax: Axes) -> None:
    """Put the legend of ``ax`` above the figure, in one row if it fits, else two."""
    handles, labels = ax.get_legend_handles_labels()
    # One row when it fits the figure's width (about 95 characters at 8 pt), else two, or as
    # many as the longest labels need to stay within the width (a summary's run labels).
    ncols = len(labels) if sum(len(t) + 6 for t in labels) <= 95 else -(-len(labels) // 2)
    widest = max((len(t) + 6 for t in labels), default=1)
    ncols = min(ncols, max(95 // widest, 1))
    fig.legend(
        handles,
        labels,
        loc="upper center",
        bbox_to_anchor=(0.5, 1.0),
        bbox_transform=fig.transFigure,
        borderaxespad=0.3,
        ncols=max(ncols, 1),
        frameon=False,
        fontsize=8,
    )
