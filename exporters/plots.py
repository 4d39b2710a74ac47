"""Report plots: matplotlib figures rendered to self-contained SVG (HTML) and PNG (PDF).

Every plot is drawn on a :class:`matplotlib.figure.Figure` built directly: no pyplot, no
backend switch, no rcParams changes and no display, so nothing is shared between renders
and no GUI backend is needed. Long series are decimated for *drawing only*: a line never
carries more than ``max_points`` vertices, while every statistic in the report is
computed from all poses by the core.

Colours follow the framework paper's Fig. 5: ground truth cyan, the first estimate
magenta (RTAB-Map there), the second green (ISAAC there), further estimates in other
distinct colours.
"""

from __future__ import annotations

import base64
import io
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, TypeAlias

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure

from loceval._typing import BoolArray, FloatArray, IntArray, StampsNs
from loceval.evaluation import EstimateResult, EvaluationConfig, EvaluationResult
from loceval.metrics import ErrorSeries

__all__ = [
    "DEFAULT_MAX_POINTS",
    "ESTIMATE_COLOURS",
    "MAX_SPAN_MARKERS",
    "MIN_GAP_WIDTH_SHARE",
    "PNG_DPI",
    "RASTER_DPI",
    "RASTER_MIN_POINTS",
    "REFERENCE_COLOUR",
    "SIDE_VIEW_MIN_Z_SPAN_M",
    "ImageFormat",
    "Plot",
    "decimate_minmax",
    "decimate_uniform",
    "describe_rpe_step",
    "envelope",
    "estimate_colour",
    "failing_span_markers",
    "is_3d",
    "plot_ate_over_time",
    "plot_ate_path",
    "plot_error_cdf",
    "plot_overlay_xy",
    "plot_rpe_over_time",
    "plot_side_views",
    "render_plots",
]

DEFAULT_MAX_POINTS = 5000
"""Most vertices drawn per line; keeps a 1,000,000-pose report small and fast."""
SIDE_VIEW_MIN_Z_SPAN_M = 0.05
"""The path counts as 3D (x-z and y-z views drawn) when the reference's heights span more."""
MAX_SPAN_MARKERS = 5
"""Failing stretches numbered on the maps (the worst first; the verdict table lists them)."""

REFERENCE_COLOUR = "#00b5d8"
"""Ground truth: cyan (the framework paper's Fig. 5), darkened a little to read on white."""
ESTIMATE_COLOURS: tuple[str, ...] = (
    "#d4009a",  # magenta (RTAB-Map in the paper's Fig. 5)
    "#1f9e34",  # green (ISAAC in the paper's Fig. 5)
    "#f58a07",  # orange
    "#3b4cc0",  # blue
    "#8c564b",  # brown
    "#6b6b6b",  # grey
    "#b8a700",  # olive
    "#7b2cbf",  # violet
)
"""Distinct estimate colours in order of the estimates."""
GAP_COLOUR = "#9e9e9e"
TOLERANCE_COLOUR = "#c62828"

MIN_GAP_WIDTH_SHARE = 0.003
"""Tracking-loss bands are drawn at least this share of the time axis wide."""
ENVELOPE_DIVISOR = 5
"""A series longer than ``max_points`` is drawn as a band of ``max_points / 5`` buckets
(about one per pixel column of the plot): each bucket's smallest and largest value."""
RASTER_MIN_POINTS = 500
"""An error-coloured path with more segments is embedded as a bitmap inside the SVG (axes,
labels and the colour bar stay vector): thousands of separately coloured SVG segments
would make the HTML large and WeasyPrint slow."""
RASTER_DPI = 150
"""Resolution of those bitmaps."""

PNG_DPI = 200
"""Resolution of PNG plots (the PDF's; print quality on A4)."""

ImageFormat: TypeAlias = Literal["svg", "png"]
"""How a plot is encoded: SVG for the HTML, PNG for the PDF (WeasyPrint draws SVG slowly)."""

_NS_PER_S = 1_000_000_000
_MIN_ERROR_AXIS = 0.01
_WIDTH_IN = 7.0
# plasma without its palest yellow, so the largest errors stay visible on white paper.
_ERROR_CMAP = ListedColormap(
    np.asarray(colormaps["plasma"](np.linspace(0.0, 0.88, 256)), dtype=np.float64),
    name="plasma_print",
)


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


def estimate_colour(index: int) -> str:
    """Return the colour of the ``index``-th estimate (cycling after eight)."""
    return ESTIMATE_COLOURS[index % len(ESTIMATE_COLOURS)]


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


def _breaks(stamps_ns: StampsNs, kept: IntArray, max_gap_ns: int) -> BoolArray:
    """Return, per kept sample but the last, whether a time gap lies before the next one."""
    jump = np.diff(stamps_ns) > max_gap_ns
    before = np.concatenate(([0], np.cumsum(jump, dtype=np.int64)))
    out: BoolArray = np.diff(before[kept]) > 0
    return out


def _with_nan_breaks(
    columns: Sequence[FloatArray], stamps_ns: StampsNs, kept: IntArray, max_gap_ns: int
) -> list[FloatArray]:
    """Pick ``kept`` samples of each column and insert NaN where a gap lies between two."""
    picked = [np.asarray(c, dtype=np.float64)[kept] for c in columns]
    if kept.size < 2:
        return picked
    where = np.flatnonzero(_breaks(stamps_ns, kept, max_gap_ns)) + 1
    return [np.insert(c, where, np.nan) for c in picked]


def _seconds(stamps_ns: StampsNs, t0_ns: int) -> FloatArray:
    out: FloatArray = (stamps_ns - np.int64(t0_ns)).astype(np.float64) / _NS_PER_S
    return out


def _max_gap_ns(result: EvaluationResult) -> int:
    return round(result.config.max_gap_s * _NS_PER_S)


def _dense(vertices: FloatArray | IntArray) -> bool:
    return int(vertices.shape[0]) > RASTER_MIN_POINTS


_SVG_NUMBER = re.compile(rb"(\d\.\d\d)\d+")
_SVG_PATH_DATA = re.compile(rb' d="[^"]*"')


def _svg(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="svg", dpi=RASTER_DPI, metadata={"Date": None, "Creator": "loceval"})
    # Path coordinates are points (1/72 in); matplotlib writes six decimals. Two (1/7200 in)
    # are far below what any screen or printer shows and make the SVG a third smaller.
    return _SVG_PATH_DATA.sub(lambda m: _SVG_NUMBER.sub(rb"\1", m.group(0)), buf.getvalue())


def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=PNG_DPI, metadata={"Software": "loceval"})
    return buf.getvalue()


def _plot(
    fig: Figure, formats: Sequence[ImageFormat], *, key: str, title: str, caption: str
) -> Plot:
    """Encode a finished figure in the requested formats (drawn once per format)."""
    svg = png = None
    if "svg" in formats:
        svg = _svg(fig)
        # The constrained layout is settled by the first save; freezing it spares the
        # second format another layout pass.
        fig.set_layout_engine("none")
    if "png" in formats:
        png = _png(fig)
    return Plot(key=key, title=title, caption=caption, svg=svg, png=png)


def _new_figure(height_in: float) -> Figure:
    return Figure(figsize=(_WIDTH_IN, height_in), dpi=150, layout="constrained")


def _style(ax: Axes) -> None:
    ax.grid(visible=True, color="#e0e0e0", linewidth=0.6)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def _legend_above(fig: Figure, ax: Axes) -> None:
    handles, labels = ax.get_legend_handles_labels()
    # One row when it fits the figure's width (about 95 characters at 8 pt), else two.
    ncols = len(labels) if sum(len(t) + 6 for t in labels) <= 95 else -(-len(labels) // 2)
    fig.legend(
        handles,
        labels,
        loc="outside upper center",
        ncols=max(ncols, 1),
        frameon=False,
        fontsize=8,
    )


def _xy_figure_height(result: EvaluationResult, *, plot_width_in: float) -> float:
    """Height for an equal-aspect x-y plot of the paths, so little paper is wasted."""
    xy = [result.reference.positions_xyz[:, :2]]
    xy.extend(e.aligned.positions_xyz[:, :2] for e in result.estimates)
    lo = np.min([p.min(axis=0) for p in xy if p.size], axis=0)
    hi = np.max([p.max(axis=0) for p in xy if p.size], axis=0)
    dx, dy = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    ratio = 1.0 if dx <= 0 else dy / dx
    return float(np.clip(plot_width_in * ratio, 2.6, 7.5)) + 1.2


def is_3d(result: EvaluationResult) -> bool:
    """Whether the side views are worth drawing: the reference's heights span > 5 cm."""
    z = result.reference.positions_xyz[:, 2]
    return bool(z.size) and float(np.ptp(z)) > SIDE_VIEW_MIN_Z_SPAN_M


def failing_span_markers(estimate: EstimateResult) -> list[tuple[int, float, float]]:
    """Return ``(number, x, y)`` of the worst failing stretches, numbered as in the verdict."""
    if estimate.verdict is None:
        return []
    spans = estimate.verdict.failing_spans[:MAX_SPAN_MARKERS]
    return [
        (k, span.max_error_position_xyz[0], span.max_error_position_xyz[1])
        for k, span in enumerate(spans, start=1)
    ]


def _draw_reference_xy(
    ax: Axes,
    result: EvaluationResult,
    max_points: int,
    axes_ij: tuple[int, int] = (0, 1),
    *,
    on_top: bool = False,
) -> None:
    ref = result.reference
    kept = decimate_uniform(len(ref), max_points)
    a, b = _with_nan_breaks(
        [ref.positions_xyz[:, axes_ij[0]], ref.positions_xyz[:, axes_ij[1]]],
        ref.stamps_ns,
        kept,
        _max_gap_ns(result),
    )
    # Under an error-coloured path the truth is a wide band; over noisy estimates it is
    # drawn last and thinner, so it stays visible.
    ax.plot(
        a,
        b,
        color=REFERENCE_COLOUR,
        linewidth=1.5 if on_top else 2.2,
        zorder=4 if on_top else 2,
        label=_reference_label(result),
    )


def _reference_label(result: EvaluationResult) -> str:
    name = result.reference.name or "reference"
    return f"{name} (ground truth)"


def _draw_estimate(
    ax: Axes,
    result: EvaluationResult,
    k: int,
    max_points: int,
    axes_ij: tuple[int, int] = (0, 1),
) -> None:
    e = result.estimates[k]
    aligned = e.aligned
    kept = decimate_uniform(len(aligned), max_points)
    a, b = _with_nan_breaks(
        [aligned.positions_xyz[:, axes_ij[0]], aligned.positions_xyz[:, axes_ij[1]]],
        aligned.stamps_ns,
        kept,
        _max_gap_ns(result),
    )
    ax.plot(
        a,
        b,
        color=estimate_colour(k),
        linewidth=1.0,
        alpha=0.85,
        label=e.name or f"estimate {k + 1}",
    )


def _mark_start(ax: Axes, result: EvaluationResult) -> None:
    start = result.reference.positions_xyz[0]
    ax.plot(
        [start[0]],
        [start[1]],
        marker="o",
        markersize=7,
        markerfacecolor="white",
        markeredgecolor="black",
        linestyle="none",
        label="start",
        zorder=5,
    )


def plot_overlay_xy(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """Top-down (x-y) overlay of the reference and every aligned estimate."""
    fig = _new_figure(_xy_figure_height(result, plot_width_in=_WIDTH_IN - 0.8))
    ax = fig.add_subplot()
    _draw_reference_xy(ax, result, max_points, on_top=True)
    for k in range(len(result.estimates)):
        _draw_estimate(ax, result, k, max_points)
    _mark_start(ax, result)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    _style(ax)
    _legend_above(fig, ax)
    names = ", ".join(e.name or f"estimate {k + 1}" for k, e in enumerate(result.estimates))
    return _plot(
        fig,
        formats,
        key="overlay_xy",
        title="Paths from above (x-y)",
        caption=(
            f"The ground truth in cyan and the aligned estimates ({names}) seen from "
            "above; the circle marks the start."
        ),
    )


def plot_ate_path(
    result: EvaluationResult,
    index: int,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """Top-down path of one estimate coloured by its ATE, with failing stretches numbered."""
    e = result.estimates[index]
    name = e.name or f"estimate {index + 1}"
    ate = e.ate_translation.values
    kept = decimate_minmax(ate, max_points)
    xy = e.aligned.positions_xyz[kept, :2]
    segments = np.stack([xy[:-1], xy[1:]], axis=1)
    keep_segment = ~_breaks(e.aligned.stamps_ns, kept, _max_gap_ns(result))
    # Each drawn segment takes the larger error of its two ends, so a peak shows.
    seg_err = np.maximum(ate[kept][:-1], ate[kept][1:])
    vmax = float(np.percentile(ate, 99.5)) if ate.size else 1.0
    tolerance = e.verdict.tolerance.distance_m if e.verdict is not None else None
    if tolerance is not None:
        vmax = max(vmax, tolerance * 1.25)
    vmax = max(vmax, 1e-6)
    fig = _new_figure(_xy_figure_height(result, plot_width_in=_WIDTH_IN - 1.8))
    ax = fig.add_subplot()
    _draw_reference_xy(ax, result, max_points)
    collection = LineCollection(
        list(segments[keep_segment]),
        cmap=_ERROR_CMAP,
        norm=Normalize(0.0, vmax),
        linewidths=1.8,
        capstyle="round",
        zorder=3,
        rasterized=_dense(segments),
    )
    collection.set_array(seg_err[keep_segment])
    ax.add_collection(collection)
    ax.update_datalim(xy)
    ax.autoscale_view()
    colorbar = fig.colorbar(
        collection, ax=ax, extend="max" if float(ate.max()) > vmax else "neither", shrink=0.85
    )
    colorbar.set_label("ATE [m]")
    if tolerance is not None:
        colorbar.ax.axhline(tolerance, color="black", linewidth=1.2)
        colorbar.ax.text(
            -0.15,
            tolerance,
            "tolerance",
            transform=colorbar.ax.get_yaxis_transform(),
            ha="right",
            va="center",
            fontsize=7,
        )
    for number, x, y in failing_span_markers(e):
        ax.annotate(
            str(number),
            (x, y),
            xytext=(9, 9),
            textcoords="offset points",
            fontsize=8,
            fontweight="bold",
            ha="center",
            va="center",
            bbox={"boxstyle": "circle,pad=0.25", "fc": "white", "ec": TOLERANCE_COLOUR},
            arrowprops={"arrowstyle": "-", "color": TOLERANCE_COLOUR, "linewidth": 0.8},
            zorder=6,
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    _style(ax)
    caption = (
        f"{name}'s aligned path coloured by its absolute trajectory error (ATE) at each "
        "pose, over the ground truth in cyan."
    )
    if tolerance is not None and e.verdict is not None and e.verdict.failing_spans:
        caption += (
            " Numbered circles mark where the worst stretches beyond the tolerance peak "
            "(see the verdict)."
        )
    return _plot(
        fig,
        formats,
        key=f"ate_path_{index}",
        title=f"{name}: error along the path",
        caption=caption,
    )


def _shade_gaps(ax: Axes, result: EvaluationResult, t0_ns: int) -> None:
    gaps = result.reference.gaps(_max_gap_ns(result))
    if not gaps:
        return
    spans = np.asarray(gaps, dtype=np.int64)
    starts = _seconds(spans[:, 0], t0_ns)
    ends = _seconds(spans[:, 1], t0_ns)
    # A 2 s gap in a 3 h recording is narrower than a pixel: draw every gap at least
    # 0.3 % of the time axis wide so it shows.
    total_s = float(result.reference.duration_s)
    min_width = MIN_GAP_WIDTH_SHARE * total_s
    centre = 0.5 * (starts + ends)
    half = 0.5 * np.maximum(ends - starts, min_width)
    starts, ends = centre - half, centre + half
    boxes = np.stack(
        [
            np.stack([starts, np.zeros_like(starts)], axis=1),
            np.stack([starts, np.ones_like(starts)], axis=1),
            np.stack([ends, np.ones_like(starts)], axis=1),
            np.stack([ends, np.zeros_like(starts)], axis=1),
        ],
        axis=1,
    )
    ax.add_collection(
        PolyCollection(
            list(boxes),
            transform=ax.get_xaxis_transform(),
            facecolors=GAP_COLOUR,
            edgecolors=GAP_COLOUR,
            alpha=0.35,
            linewidths=0.5,
            label="tracking loss (reference gap)",
        ),
        autolim=False,
    )


def envelope(
    times_s: FloatArray, values: FloatArray, stamps_ns: StampsNs, *, buckets: int, max_gap_ns: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per-bucket minimum, maximum and mean of a long series, for drawing it as a band.

    Consecutive samples fall into about ``buckets`` equal buckets; a bucket never spans a
    time gap longer than ``max_gap_ns`` (tracking loss), and a NaN row separates the
    stretches on either side of a gap, so the band breaks there.

    Args:
        times_s: (N,) sample times, seconds.
        values: (N,) the series.
        stamps_ns: (N,) the sample stamps (to find the gaps).
        buckets: about how many buckets to make.
        max_gap_ns: a longer interval between samples is a gap.

    Returns:
        ``(t, lo, hi, mean)``: bucket centre times, minima, maxima and means, (B,) each
        with NaN rows at the gaps.
    """
    n = int(values.shape[0])
    size = max(1, -(-n // max(buckets, 1)))
    jump = np.diff(stamps_ns) > max_gap_ns
    stretch = np.concatenate(([0], np.cumsum(jump, dtype=np.int64)))
    stretch_start = np.concatenate(([0], np.flatnonzero(jump) + 1))
    local = np.arange(n, dtype=np.int64) - stretch_start[stretch]
    key = stretch * (n + 1) + local // size
    starts = np.flatnonzero(np.concatenate(([True], np.diff(key) != 0)))
    ends = np.concatenate((starts[1:], [n])) - 1
    lo = np.minimum.reduceat(values, starts)
    hi = np.maximum.reduceat(values, starts)
    mean = np.add.reduceat(values, starts) / (ends - starts + 1)
    centre = 0.5 * (times_s[starts] + times_s[ends])
    breaks = np.flatnonzero(np.diff(stretch[starts]) != 0) + 1
    out_t: FloatArray = np.insert(centre, breaks, np.nan)
    out_lo: FloatArray = np.insert(lo, breaks, np.nan)
    out_hi: FloatArray = np.insert(hi, breaks, np.nan)
    out_mean: FloatArray = np.insert(mean, breaks, np.nan)
    return out_t, out_lo, out_hi, out_mean


def _draw_series(
    ax: Axes,
    result: EvaluationResult,
    series: ErrorSeries,
    k: int,
    *,
    t0_ns: int,
    max_points: int,
) -> None:
    name = result.estimates[k].name or f"estimate {k + 1}"
    colour = estimate_colour(k)
    times = _seconds(series.stamps_ns, t0_ns)
    if len(series) <= max_points:
        t, v = _with_nan_breaks(
            [times, series.values],
            series.stamps_ns,
            np.arange(len(series), dtype=np.intp),
            _max_gap_ns(result),
        )
        ax.plot(t, v, color=colour, linewidth=0.8, label=name)
        return
    # Too many samples to draw one by one: a light band between each bucket's smallest and
    # largest error (every peak survives) under a line of the bucket means. At print
    # resolution it shows what the zigzag line would, stays readable where estimates
    # overlap, and is two light paths instead of thousands of overlapping strokes.
    t, lo, hi, mean = envelope(
        times,
        series.values,
        series.stamps_ns,
        buckets=max_points // ENVELOPE_DIVISOR,
        max_gap_ns=_max_gap_ns(result),
    )
    ax.fill_between(t, lo, hi, color=colour, alpha=0.3, linewidth=0.0)
    ax.plot(t, mean, color=colour, linewidth=0.9, label=name)


def _time_plot(
    result: EvaluationResult,
    rows: list[tuple[str, list[ErrorSeries | None]]],
    *,
    tolerance_row: int | None,
    max_points: int,
) -> Figure:
    t0_ns = int(result.reference.stamps_ns[0])
    fig = _new_figure(1.2 + 1.45 * len(rows))
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    for r, (label, series_list) in enumerate(rows):
        ax = axes[r]
        _shade_gaps(ax, result, t0_ns)
        for k, series in enumerate(series_list):
            if series is not None:
                _draw_series(ax, result, series, k, t0_ns=t0_ns, max_points=max_points)
        tol = result.config.tolerance
        if r == tolerance_row and tol is not None:
            ax.axhline(
                tol.distance_m,
                color=TOLERANCE_COLOUR,
                linestyle="--",
                linewidth=1.0,
                label=f"tolerance {tol.distance_m:g} m",
            )
        ax.set_ylabel(label)
        # A floor on the axis range: rounding noise (1e-14 °) must not look like an error.
        ax.set_ylim(0.0, max(ax.get_ylim()[1], _MIN_ERROR_AXIS))
        _style(ax)
        if r == 0:
            _legend_above(fig, ax)
    axes[-1].set_xlabel("time since the start of the reference [s]")
    return fig


def _time_plot_notes(
    result: EvaluationResult,
    rows: list[tuple[str, list[ErrorSeries | None]]],
    max_points: int,
) -> str:
    """The caption's explanation of what is drawn, only for what is in the figure."""
    max_gap_ns = _max_gap_ns(result)
    notes = ""
    gaps = result.reference.gaps(max_gap_ns)
    if gaps:
        notes += " Grey bands are tracking loss of the reference (not evaluated)"
        min_width_ns = MIN_GAP_WIDTH_SHARE * result.reference.duration_s * _NS_PER_S
        notes += (
            "; short ones are drawn wider so they show."
            if any(b - a < min_width_ns for a, b in gaps)
            else "."
        )
    series = [s for _, row in rows for s in row if s is not None]
    if any(bool((np.diff(s.stamps_ns) > max_gap_ns).any()) for s in series):
        notes += (
            f" A break in a line is a stretch of more than {result.config.max_gap_s:g} s "
            "without evaluated poses."
        )
    if any(len(s) > max_points for s in series):
        notes += (
            " Long series are drawn as a light band from the smallest to the largest error "
            "of each time slice, with a line through the slice means."
        )
    return notes


def plot_ate_over_time(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """ATE (translation, and rotation when known) over time with tracking loss shaded."""
    rows: list[tuple[str, list[ErrorSeries | None]]] = [
        ("ATE [m]", [e.ate_translation for e in result.estimates])
    ]
    if any(e.ate_rotation is not None for e in result.estimates):
        rows.append(("ATE rotation [°]", [e.ate_rotation for e in result.estimates]))
    fig = _time_plot(result, rows, tolerance_row=0, max_points=max_points)
    return _plot(
        fig,
        formats,
        key="ate_time",
        title="Absolute trajectory error over time",
        caption=(
            "Distance between each aligned estimate pose and the ground truth at the same "
            "time." + _time_plot_notes(result, rows, max_points)
        ),
    )


def plot_rpe_over_time(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """RPE (translation, and rotation when known) over time with tracking loss shaded."""
    rows: list[tuple[str, list[ErrorSeries | None]]] = [
        ("RPE [m]", [e.rpe_translation for e in result.estimates])
    ]
    if any(e.rpe_rotation is not None for e in result.estimates):
        rows.append(("RPE rotation [°]", [e.rpe_rotation for e in result.estimates]))
    fig = _time_plot(result, rows, tolerance_row=None, max_points=max_points)
    cfg = result.config
    return _plot(
        fig,
        formats,
        key="rpe_time",
        title="Relative pose error over time",
        caption=(
            f"Error of the motion over each step of {describe_rpe_step(cfg)}, at the step's "
            "start." + _time_plot_notes(result, rows, max_points)
        ),
    )


def plot_error_cdf(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """Cumulative distribution of ATE with the thresholds (the reference-system paper's Fig. 7)."""
    fig = _new_figure(4.0)
    ax = fig.add_subplot()
    thresholds = result.config.thresholds_m
    for k, e in enumerate(result.estimates):
        values, shares = e.ate_translation.cdf()
        kept = decimate_uniform(values.size, max_points)
        ax.step(
            values[kept],
            100.0 * shares[kept],
            where="post",
            color=estimate_colour(k),
            linewidth=1.2,
            label=e.name or f"estimate {k + 1}",
        )
        shares_at = [100.0 * e.within[t] for t in thresholds if t in e.within]
        ax.plot(
            [t for t in thresholds if t in e.within],
            shares_at,
            linestyle="none",
            marker="o",
            markersize=4,
            color=estimate_colour(k),
        )
    for t in thresholds:
        ax.axvline(t, color="#616161", linestyle=":", linewidth=1.0)
        ax.text(
            t,
            1.01,
            f"{t:g} m",
            transform=ax.get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize=7,
            color="#424242",
        )
    tol = result.config.tolerance
    if tol is not None:
        ax.plot(
            [tol.distance_m],
            [100.0 * tol.share],
            marker="P",
            markersize=9,
            color=TOLERANCE_COLOUR,
            linestyle="none",
            label=f"tolerance: {tol}",
            zorder=5,
        )
    ax.set_xlim(left=0.0)
    ax.set_ylim(0.0, 101.0)
    ax.set_xlabel("ATE [m]")
    ax.set_ylabel("poses with error ≤ x [%]")
    _style(ax)
    ax.legend(loc="lower right", fontsize=8, frameon=True, framealpha=0.9)
    caption = (
        "Share of poses whose error is at most the value on the x-axis; dotted lines are the "
        "thresholds, dots the shares within them."
    )
    if tol is not None:
        caption += " An estimate meets the tolerance when its curve passes above the red cross."
    return _plot(
        fig,
        formats,
        key="error_cdf",
        title="Error distribution (CDF)",
        caption=caption,
    )


def plot_side_views(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> Plot:
    """Side views (x-z and y-z) of the reference and every aligned estimate."""
    fig = _new_figure(5.2)
    axes = fig.subplots(2, 1)
    for ax, (i, label) in zip(axes, ((0, "x"), (1, "y")), strict=True):
        _draw_reference_xy(ax, result, max_points, axes_ij=(i, 2), on_top=True)
        for k in range(len(result.estimates)):
            _draw_estimate(ax, result, k, max_points, axes_ij=(i, 2))
        ax.set_xlabel(f"{label} [m]")
        ax.set_ylabel("z [m]")
        _style(ax)
    _legend_above(fig, axes[0])
    return _plot(
        fig,
        formats,
        key="side_views",
        title="Side views (x-z, y-z)",
        caption=(
            "The paths seen from the side; the height axis is stretched to show height errors."
        ),
    )


def describe_rpe_step(config: EvaluationConfig) -> str:
    """Return the RPE step in words: ``1 frame``, ``5 frames``, ``0.5 m``, ``1 s``."""
    delta, unit = config.rpe_delta, config.rpe_unit.value
    if unit == "frames":
        return f"{delta:g} frame{'' if delta == 1 else 's'}"
    return f"{delta:g} {unit}"


def render_plots(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
) -> tuple[Plot, ...]:
    """Render every plot of the report, in report order.

    Args:
        result: the evaluation.
        max_points: most vertices drawn per line (drawing only; statistics use all poses).
        formats: the encodings to produce from each figure (SVG for HTML, PNG for PDF).

    Returns:
        The overlay, one error-coloured path per estimate, ATE and RPE over time, the CDF
        and, for a 3D path, the side views.
    """
    plots = [plot_overlay_xy(result, max_points=max_points, formats=formats)]
    plots.extend(
        plot_ate_path(result, k, max_points=max_points, formats=formats)
        for k in range(len(result.estimates))
    )
    plots.append(plot_ate_over_time(result, max_points=max_points, formats=formats))
    plots.append(plot_rpe_over_time(result, max_points=max_points, formats=formats))
    plots.append(plot_error_cdf(result, max_points=max_points, formats=formats))
    if is_3d(result):
        plots.append(plot_side_views(result, max_points=max_points, formats=formats))
    return tuple(plots)
