"""The floor plan under the plan-view plots: a building model cut at the device's height.

:func:`floor_plan_segments` cuts the building model of the options (``building``: a mesh,
an IFC or a DXF floor plan) once per report, in the evaluation frame (placed by the site
transform, or an IFC's own map conversion); :func:`draw_floor_plan` draws those segments as
light grey lines under the paths and frames the building with them (its outer walls are in
the figure), unless the model is far larger than the paths (a campus: then the plot keeps
the paths' extent, as the viewer's first view does, :data:`FRAME_BUILDING_UP_TO`). The
caption mentions the building only when some of it lies in the figure
(:func:`floor_plan_note`): the report never claims a building it did not draw.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection

from exporters.cad.building import (
    FRAME_BUILDING_UP_TO,
    georeferenced_options,
    read_underlay,
    section_segments,
)
from exporters.options import ExportOptions
from loceval.core.arrays import FloatArray

__all__ = [
    "FLOOR_PLAN_GID",
    "FRAME_BUILDING_UP_TO",
    "draw_floor_plan",
    "floor_plan_note",
    "floor_plan_segments",
]

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


def draw_floor_plan(ax: Axes, segments: FloatArray | None, paths_xy: FloatArray) -> bool:
    """Draw the floor plan as light grey lines under everything; frame it with the paths.

    Args:
        ax: the plan-view axes.
        segments: (K, 2, 2) floor-plan segments (evaluation frame, metres), or None.
        paths_xy: (N, 2) the points the figure shows (paths or control points).

    Returns:
        Whether any of the floor plan lies in the figure (the caption may mention it).
    """
    if segments is None or not len(segments):
        return False
    ends = segments.reshape(-1, 2)
    lines = LineCollection(
        list(segments), colors=_GREY, linewidths=_LINE_WIDTH, zorder=0, label="_floor plan"
    )
    lines.set_gid(FLOOR_PLAN_GID)
    ax.add_collection(lines, autolim=False)
    if not len(paths_xy):
        ax.update_datalim(ends)
        return True
    lo, hi = paths_xy.min(axis=0), paths_xy.max(axis=0)
    paths_size = max(float(np.linalg.norm(hi - lo)), 1.0)
    building_size = float(np.linalg.norm(ends.max(axis=0) - ends.min(axis=0)))
    if building_size <= FRAME_BUILDING_UP_TO * paths_size:
        ax.update_datalim(ends)  # the outer walls are in the figure
        return True
    # a campus: the figure keeps the paths' extent; some of the plan may lie in it
    margin = 0.05 * (hi - lo)
    seg_lo, seg_hi = segments.min(axis=1), segments.max(axis=1)
    overlaps = np.all((seg_hi >= lo - margin) & (seg_lo <= hi + margin), axis=1)
    return bool(overlaps.any())


def floor_plan_note(drawn: bool) -> str:  # noqa: FBT001  (the one argument)
    """Return the caption's sentence about the floor plan ("" when none is in the figure)."""
    if not drawn:
        return ""
    return " Grey lines: the building model cut at the device's median height."
