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

from typing import TYPE_CHECKING, Final

import numpy as np

from exporters.cad.building import (
    FRAME_BUILDING_UP_TO,
    georeferenced_options,
    read_underlay,
    section_segments,
)
from exporters.options import ExportOptions
from exporters.plots.svg.axes import Axes as KitAxes
from loceval.core.arrays import FloatArray

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = [
    "FLOOR_PLAN_GID",
    "FRAME_BUILDING_UP_TO",
    "draw_floor_plan",
    "floor_plan_note",
    "floor_plan_segments",
]

FLOOR_PLAN_GID: Final = "floor-plan"
"""The SVG group id of the floor plan's lines."""
_GREY: Final = "#cccccc"
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


def draw_floor_plan(ax: KitAxes | Axes, segments: FloatArray | None, paths_xy: FloatArray) -> bool:
    """Draw the floor plan as light grey lines under everything; frame it with the paths.

    Args:
        ax: the plan-view axes: the figure kit's (:mod:`exporters.plots.svg`) or matplotlib's.
        segments: (K, 2, 2) floor-plan segments (evaluation frame, metres), or None.
        paths_xy: (N, 2) the points the figure shows (paths or control points).

    Returns:
        Whether any of the floor plan lies in the figure (the caption may mention it).
    """
    if segments is None or not len(segments):
        return False
    ends = segments.reshape(-1, 2)
    if isinstance(ax, KitAxes):
        ax.segments(
            segments,
            np.zeros(len(segments), dtype=np.intp),
            [_GREY],
            width=_LINE_WIDTH,
            z=0.0,
            group=FLOOR_PLAN_GID,
            autolim=False,
        )
    else:
        from matplotlib.collections import LineCollection  # noqa: PLC0415  (matplotlib's plots)

        lines = LineCollection(
            list(segments), colors=_GREY, linewidths=_LINE_WIDTH, zorder=0, label="_floor plan"
        )
        lines.set_gid(FLOOR_PLAN_GID)
        ax.add_collection(lines, autolim=False)
    framed = _frames_building(segments, paths_xy)
    if framed:  # the outer walls are in the figure
        if isinstance(ax, KitAxes):
            ax.x.add(ends[:, 0])
            ax.y.add(ends[:, 1])
        else:
            ax.update_datalim(ends)
        return True
    # a campus: the figure keeps the paths' extent; some of the plan may lie in it
    lo, hi = paths_xy.min(axis=0), paths_xy.max(axis=0)
    margin = 0.05 * (hi - lo)
    seg_lo, seg_hi = segments.min(axis=1), segments.max(axis=1)
    overlaps = np.all((seg_hi >= lo - margin) & (seg_lo <= hi + margin), axis=1)
    return bool(overlaps.any())


def _frames_building(segments: FloatArray, paths_xy: FloatArray) -> bool:
    """Whether the figure takes in the whole building (not far larger than the paths)."""
    if not len(paths_xy):
        return True
    ends = segments.reshape(-1, 2)
    paths_size = max(float(np.linalg.norm(np.ptp(paths_xy, axis=0))), 1.0)
    building_size = float(np.linalg.norm(ends.max(axis=0) - ends.min(axis=0)))
    return building_size <= FRAME_BUILDING_UP_TO * paths_size


def floor_plan_note(drawn: bool) -> str:  # noqa: FBT001  (the one argument)
    """Return the caption's sentence about the floor plan ("" when none is in the figure)."""
    if not drawn:
        return ""
    return " Grey lines: the building model cut at the device's median height."
