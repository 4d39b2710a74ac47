"""The DXF's map layers: the robot's map on the building plan (when a map was measured).

- ``map plan``: the plan's walls the map was measured against, grey ``LINE`` s;
- ``map walls``: the map's wall cells as ``POINT`` s coloured by their distance to the plan
  (the report's colours and bins, :func:`exporters.colours.map_bins`), at most
  :data:`MAX_CAD_CELLS` of them, evenly spread (every cell is in ``map_cells.csv``);
- ``map clutter``: the cells farther than the clutter distance after the fit (magenta).

Cells and walls sit at the reference's median height, where the plan was cut.

``excursions`` (any evaluation): each estimate's aligned path while the reference was lost
for longer than the minimum excursion, with its duration, length and drift as a label.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from ezdxf import colors
from ezdxf.document import Drawing
from ezdxf.layouts.layout import Modelspace

from exporters.cad.excursions import EXCURSION_LAYER, EXCURSION_RGB, placed_excursions
from exporters.cad.placement import Placement
from exporters.colours import map_bins
from loceval.core.arrays import FloatArray

__all__ = ["MAX_CAD_CELLS", "add_excursion_layer", "add_map_layers"]

MAX_CAD_CELLS: Final = 20_000
"""Most wall cells drawn into a CAD file (one entity each)."""
_PLAN_RGB: Final = (158, 158, 158)
_CLUTTER_RGB: Final = (194, 24, 91)


def placed_cells(placement: Placement) -> tuple[FloatArray, FloatArray, np.ndarray] | None:
    """Return the kept cells in model units, their distances and clutter flags (or None)."""
    found = placement.result.map
    if found is None:
        return None
    step = max(1, -(-len(found.cells_xy) // MAX_CAD_CELLS))
    xy = found.cells_xy[::step]
    z = float(np.median(placement.result.reference.positions_xyz[:, 2]))
    xyz = placement.to_model(np.column_stack([xy, np.full(len(xy), z)]))
    return xyz, found.distance_m[::step], found.clutter[::step]


def add_map_layers(doc: Drawing, msp: Modelspace, placement: Placement) -> None:
    """Add the plan, wall-cell and clutter layers (nothing without a map)."""
    found = placement.result.map
    cells = placed_cells(placement)
    if found is None or cells is None:
        return
    xyz, distance, clutter = cells
    z = float(np.median(placement.result.reference.positions_xyz[:, 2]))
    _layer(doc, "map plan", _PLAN_RGB, "loceval: the building plan the map was measured against")
    ends = found.plan_xy.reshape(-1, 2)
    plan = placement.to_model(np.column_stack([ends, np.full(len(ends), z)])).reshape(-1, 2, 3)
    for a, b in plan.tolist():  # one entity per plan wall
        msp.add_line(a, b, dxfattribs={"layer": "map plan"})
    bins = map_bins(found.distance_m, placement.result.config.thresholds_m)
    _layer(doc, "map walls", bins[0].color_rgb, "loceval: map wall cells by distance to the plan")
    _layer(doc, "map clutter", _CLUTTER_RGB, "loceval: map cells not in the plan (clutter)")
    index = np.searchsorted([b.high_m for b in bins[:-1]], distance, side="left")
    for point, k, is_clutter in zip(xyz.tolist(), index.tolist(), clutter.tolist(), strict=True):
        rgb = _CLUTTER_RGB if is_clutter else bins[k].color_rgb
        layer = "map clutter" if is_clutter else "map walls"
        msp.add_point(point, dxfattribs={"layer": layer, "true_color": colors.rgb2int(rgb)})


def _layer(doc: Drawing, name: str, rgb: tuple[int, int, int], description: str) -> None:
    layer = doc.layers.add(name)
    layer.rgb = rgb
    layer.description = description


def add_excursion_layer(doc: Drawing, msp: Modelspace, placement: Placement, text_h: float) -> None:
    """Add ``excursions``: each estimate's path outside the tracked room and its drift label."""
    placed = placed_excursions(placement)
    if not placed:
        return
    _layer(doc, EXCURSION_LAYER, EXCURSION_RGB, "loceval: estimate paths outside the tracked room")
    for path, model in placed:  # a few stretches per run
        msp.add_polyline3d(model.tolist(), dxfattribs={"layer": EXCURSION_LAYER})
        msp.add_text(
            path.label,
            height=text_h,
            dxfattribs={"layer": EXCURSION_LAYER, "insert": tuple(model[0].tolist())},
        )
