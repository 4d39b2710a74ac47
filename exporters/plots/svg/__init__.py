"""The report's own figure kit: SVG drawn directly from NumPy arrays, without matplotlib.

:mod:`~exporters.plots.svg.canvas` (a figure: its grid of axes, legend, colour bar, layout
and encoding), :mod:`~exporters.plots.svg.axes` (what an axes draws), and
:mod:`~exporters.plots.svg.ticks` and :mod:`~exporters.plots.svg.metrics` (tick values and
text widths, which the layout measures).
"""
