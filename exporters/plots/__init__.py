"""Report plots: self-contained SVG figures (the HTML and the PDF) and PNG (a WeasyPrint PDF).

Split by concern: :mod:`~exporters.plots.svg` (the figure kit the common plots are drawn
with), :mod:`~exporters.plots.mpl` (the matplotlib figures of the rarer ones),
:mod:`~exporters.plots.figure` (colours, decimation, the figure and its encoding),
:mod:`~exporters.plots.maps` (paths from above, error along the path, side views),
:mod:`~exporters.plots.series` (errors over time, the CDF) and :mod:`~exporters.plots.render`
(every plot of the report, in order).
"""

from __future__ import annotations

from exporters.plots.figure import (
    DEFAULT_MAX_POINTS,
    MAX_SPAN_MARKERS,
    REFERENCE_COLOUR,
    ImageFormat,
    Plot,
    decimate_minmax,
    decimate_uniform,
    estimate_colour,
)
from exporters.plots.maps import (
    failing_span_markers,
    is_3d,
    plot_ate_path,
    plot_overlay_xy,
    plot_side_views,
)
from exporters.plots.render import render_plots
from exporters.plots.series import (
    describe_rpe_step,
    envelope,
    plot_ate_over_time,
    plot_error_cdf,
    plot_rpe_over_time,
)

__all__ = [
    "DEFAULT_MAX_POINTS",
    "MAX_SPAN_MARKERS",
    "REFERENCE_COLOUR",
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
