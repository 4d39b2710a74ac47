"""The floor plan under the plan-view plots: a building model cut at the device's height.

:func:`floor_plan_segments` cuts the building model of the options (``building``: a mesh,
an IFC or a DXF floor plan) once per report, in the evaluation frame (placed by the site
transform, or an IFC's own map conversion); :func:`draw_floor_plan` draws those segments as
light grey lines under the paths, without widening the plot beyond the paths.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection

from exporters.cad.building import georeferenced_options, read_underlay, section_segments
from exporters.options import ExportOptions
from loceval.core.arrays import FloatArray

__all__ = ["FLOOR_PLAN_GID", "draw_floor_plan", "floor_plan_note", "floor_plan_segments"]

FLOOR_PLAN_GID: Final = "floor-plan"
"""The SVG group id of the floor plan's lines (one ``<path>`` per segment)."""
_GREY: Final = "0.8"
_LINE_WIDTH: Final = 0.6


def floor_plan_segments(heights_m: FloatArray, options: ExportOptions) -> FloatArray | None:
    """Cut the options' building model at the median of ``heights_m``, in the evaluation frame.

    Args:
        heights_m: the device's heights in the evaluation frame (the reference's z, or the
            control points' z), metres.
        options: the building model, its units and up axis, and the site transform (an
            IFC's own map conversion when no site or CRS is given).

    Returns:
        (K, 2, 2) segments in evaluation-frame metres, or None without a building model.

    Raises:
        ExportOptionsError: a building model that cannot be read.
    """
    if options.building is None:
        return None
    placed = georeferenced_options(options)
    underlay = read_underlay(options.building, units=placed.units, up=placed.building_up)
    z_m = float(np.median(heights_m)) if heights_m.size else 0.0
    return section_segments(underlay, z_m, site=placed.site)


def draw_floor_plan(ax: Axes, segments: FloatArray | None) -> None:
    """Draw the floor plan as light grey lines under everything, keeping the paths' extent."""
    if segments is None or not len(segments):
        return
    lines = LineCollection(
        list(segments), colors=_GREY, linewidths=_LINE_WIDTH, zorder=0, label="_floor plan"
    )
    lines.set_gid(FLOOR_PLAN_GID)
    ax.add_collection(lines, autolim=False)


def floor_plan_note(segments: FloatArray | None) -> str:
    """Return the caption's sentence about the floor plan ("" without one)."""
    if segments is None or not len(segments):
        return ""
    return " Grey lines: the building model cut at the device's median height."
