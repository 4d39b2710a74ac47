"""The report plots' drawing kit: colours, decimation, figures and their SVG/PNG encoding.

The report's own figures (the maps, the error series, the CDF, the clock plots) are drawn
by the figure kit of :mod:`exporters.plots.svg`: SVG written from NumPy arrays, no
matplotlib to import or to run (a report's figures took most of its second). Figures drawn
less often (trials, ranging, maps of a robot, checkpoints, summaries) are still matplotlib
figures, built by :mod:`exporters.plots.mpl`, which is imported only when one is drawn;
:func:`encode_plot` encodes either. Long series are decimated for *drawing only*: a line never
carries more than ``max_points`` vertices, while every statistic in the report is
computed from all poses by the core.

Colours follow the framework paper's Fig. 5: ground truth cyan, the first estimate
magenta (RTAB-Map there), the second green (ISAAC there), further estimates in other
distinct colours.

The drawing helpers (:func:`new_figure`, :func:`encode_plot`, ...) are shared by the plot
modules of this package and the summary report's (:mod:`exporters.summary.plots`); the
package itself re-exports only what its callers use.
"""

from __future__ import annotations

import base64
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, TypeAlias

import numpy as np

from exporters.colours import ESTIMATE_COLOURS, estimate_colour
from exporters.plots.svg.canvas import WIDTH_IN, Figure, png_of_svg
from loceval.core.arrays import BoolArray, FloatArray, IntArray, StampsNs
from loceval.core.gaps import path_breaks
from loceval.evaluation import EvaluationResult

if TYPE_CHECKING:
    from matplotlib.figure import Figure as MplFigure

__all__ = [
    "DEFAULT_MAX_POINTS",
    "ESTIMATE_COLOURS",
    "MAX_SPAN_MARKERS",
    "MIN_ERROR_AXIS",
    "MIN_GAP_WIDTH_SHARE",
    "NS_PER_S",
    "PNG_DPI",
    "RASTER_DPI",
    "REFERENCE_COLOUR",
    "SIDE_VIEW_MIN_Z_SPAN_M",
    "TOLERANCE_COLOUR",
    "WIDTH_IN",
    "FigureView",
    "ImageFormat",
    "Plot",
    "breaks_between",
    "decimate_minmax",
    "decimate_uniform",
    "encode_plot",
    "estimate_colour",
    "new_figure",
    "number_figures",
    "path_jumps",
    "reference_losses",
    "seconds_since",
    "with_nan_breaks",
]


DEFAULT_MAX_POINTS = 5000
"""Most vertices drawn per line; keeps a 1,000,000-pose report small and fast."""
SIDE_VIEW_MIN_Z_SPAN_M = 0.05
"""The path counts as 3D (x-z and y-z views drawn) when the reference's heights span more."""
MAX_SPAN_MARKERS = 5
"""Failing stretches numbered on the maps (the worst first; the verdict table lists them)."""

REFERENCE_COLOUR = "#00b5d8"
"""Ground truth: cyan (the framework paper's Fig. 5), darkened a little to read on white."""
GAP_COLOUR = "#9e9e9e"
TOLERANCE_COLOUR = "#c62828"

MIN_GAP_WIDTH_SHARE = 0.003
"""Tracking-loss bands are drawn at least this share of the time axis wide."""
ENVELOPE_DIVISOR = 5
"""A series longer than ``max_points`` is drawn as a band of ``max_points / 5`` buckets
(about one per pixel column of the plot): each bucket's smallest and largest value."""
RASTER_DPI = 150
"""Resolution of the bitmaps a matplotlib figure embeds in its SVG (a robot's map)."""

PNG_DPI = 200
"""Resolution of PNG plots (print quality on A4: the PDF WeasyPrint lays out of HTML templates
of one's own; the reports' own PDFs embed the SVG)."""

ImageFormat: TypeAlias = Literal["svg", "png"]
"""How a plot is encoded: SVG for the HTML and Typst's PDF, PNG for a PDF WeasyPrint lays out
(it draws SVG slowly)."""

NS_PER_S = 1_000_000_000
"""Nanoseconds per second."""
MIN_ERROR_AXIS = 0.01
"""Smallest upper limit of an error axis, in the error's unit."""


@dataclass(frozen=True, slots=True)
class Plot:
    """One rendered figure of the report.

    Attributes:
        key: a stable identifier (``"overlay_xy"``, ``"ate_path_0"``, ...).
        title: the figure's title in the report.
        caption: what the figure shows, in words.
        svg: the SVG document (UTF-8), if rendered.
        png: the PNG image, if rendered.
    """

    key: str
    title: str
    caption: str
    svg: bytes | None = None
    png: bytes | None = None

    def data_uri(self, image_format: ImageFormat = "svg") -> str:
        """Return the image as a ``data:`` URI for an ``<img>`` (no external file).

        Raises:
            ValueError: the plot was not rendered in that format.
        """
        data = self.svg if image_format == "svg" else self.png
        if data is None:
            msg = f"Plot {self.key!r} was not rendered as {image_format}."
            raise ValueError(msg)
        media = "image/svg+xml" if image_format == "svg" else "image/png"
        return f"data:{media};base64," + base64.b64encode(data).decode("ascii")

    def as_figure(self, number: int, image_format: ImageFormat = "svg") -> FigureView:
        """Return the plot as figure ``number`` of a report, embedded as ``image_format``."""
        return FigureView(number, self.key, self.title, self.caption, self.data_uri(image_format))


@dataclass(frozen=True, slots=True)
class FigureView:
    """A numbered figure as the report templates show it; ``src`` is a ``data:`` URI."""

    number: int
    key: str
    title: str
    caption: str
    src: str


def number_figures(plots: Iterable[Plot], image_format: ImageFormat) -> tuple[FigureView, ...]:
    """Return the plots as figures numbered from 1, embedded as ``image_format``."""
    return tuple(p.as_figure(n, image_format) for n, p in enumerate(plots, start=1))


def decimate_uniform(n: int, max_points: int) -> IntArray:
    """Return at most ``max_points`` evenly spaced indices into ``n`` samples.

    The first and last samples are always kept.
    """
    if n <= max_points:
        return np.arange(n, dtype=np.intp)
    idx = np.unique(np.linspace(0, n - 1, max(max_points, 2)).round().astype(np.intp))
    return idx.astype(np.intp, copy=False)


def decimate_minmax(values: FloatArray, max_points: int) -> IntArray:
    """Return sorted indices keeping each bucket's minimum and maximum (at most ``max_points``).

    The series is split into ``max_points // 2`` equal buckets of consecutive samples; the
    smallest and largest value of each bucket survive, so peaks (the errors that matter)
    are never decimated away. The first and last samples are always kept.
    """
    n = int(values.shape[0])
    if n <= max_points:
        return np.arange(n, dtype=np.intp)
    buckets = max(max_points // 2 - 1, 1)
    size = -(-n // buckets)  # ceil
    padded_n = buckets * size
    padded_lo = np.full(padded_n, np.inf)
    padded_hi = np.full(padded_n, -np.inf)
    padded_lo[:n] = values
    padded_hi[:n] = values
    offsets = np.arange(buckets, dtype=np.intp) * size
    lo = padded_lo.reshape(buckets, size).argmin(axis=1) + offsets
    hi = padded_hi.reshape(buckets, size).argmax(axis=1) + offsets
    keep = np.concatenate(([0, n - 1], lo, hi))
    return np.unique(keep[keep < n]).astype(np.intp, copy=False)


def breaks_between(jump: BoolArray, kept: IntArray) -> BoolArray:
    """Return, per kept sample but the last, whether a break lies before the next one.

    Args:
        jump: (N - 1,) True after each sample that ends a piece (:func:`path_jumps`).
        kept: increasing indices of the samples drawn.
    """
    before = np.concatenate(([0], np.cumsum(jump, dtype=np.int64)))
    out: BoolArray = np.diff(before[kept]) > 0
    return out


def with_nan_breaks(
    columns: Sequence[FloatArray], jump: BoolArray, kept: IntArray
) -> list[FloatArray]:
    """Pick ``kept`` samples of each column and insert NaN where a break lies between two."""
    picked = [np.asarray(c, dtype=np.float64)[kept] for c in columns]
    if kept.size < 2:
        return picked
    where = np.flatnonzero(breaks_between(jump, kept)) + 1
    return [np.insert(c, where, np.nan) for c in picked]


def seconds_since(stamps_ns: StampsNs, t0_ns: int) -> FloatArray:
    """Return the stamps as float seconds after ``t0_ns``."""
    out: FloatArray = (stamps_ns - np.int64(t0_ns)).astype(np.float64) / NS_PER_S
    return out


def _min_gap_ns(result: EvaluationResult) -> int:
    return round(result.config.max_gap_s * NS_PER_S)


def reference_losses(result: EvaluationResult) -> list[tuple[int, int]]:
    """Return the reference's tracking losses (:mod:`loceval.core.gaps`), as the result reports."""
    return result.reference.tracking_losses(_min_gap_ns(result))


def path_jumps(result: EvaluationResult, stamps_ns: StampsNs) -> BoolArray:
    """Return (N - 1,) where a line through these stamps breaks (own or reference loss)."""
    return path_breaks(stamps_ns, min_gap_ns=_min_gap_ns(result), losses=reference_losses(result))


def new_figure(height_in: float) -> Figure:
    """Return an empty figure of the report's width, ``height_in`` inches high (the kit's)."""
    return Figure(height_in=height_in, width_in=WIDTH_IN)


def encode_plot(
    fig: Figure | MplFigure,
    formats: Sequence[ImageFormat],
    *,
    key: str,
    title: str,
    caption: str,
) -> Plot:
    """Encode a finished figure in the requested formats (laid out once, drawn once per format).

    ``fig`` is a figure of the kit (:func:`new_figure`) or a matplotlib figure
    (:func:`exporters.plots.mpl.new_figure`).
    """
    if not isinstance(fig, Figure):
        from exporters.plots.mpl import encode_figure  # noqa: PLC0415  (matplotlib: lazily)

        svg, png = encode_figure(fig, formats, png_dpi=PNG_DPI, svg_dpi=RASTER_DPI)
        return Plot(key=key, title=title, caption=caption, svg=svg, png=png)
    svg_doc = fig.svg()
    png = png_of_svg(svg_doc, dpi=PNG_DPI, software="loceval") if "png" in formats else None
    return Plot(
        key=key, title=title, caption=caption, svg=svg_doc if "svg" in formats else None, png=png
    )
