"""DXF (R2013) export: each trajectory a 3D POLYLINE on its own layer, in model coordinates.

Layers, per trajectory ``<name>`` (named after the trajectory, coloured from the palette
with both an ACI and a true colour):

- ``<name>``: the path as 3D ``POLYLINE`` s (never ``LWPOLYLINE``, which has no per-vertex
  Z and would silently flatten the path), one per continuous piece: a path breaks at
  tracking loss instead of crossing it with a straight chord; ``LOCEVAL`` XDATA names its
  source;
- ``<name> markers`` (estimates): a ``POINT`` and a label at the greatest errors with a
  ``LINE`` to the reference pose;
- ``<name> ATE`` (estimates, on): the path cut into pieces coloured by ATE bin, in the
  report's colours (:meth:`~exporters.cad.placement.Placement.ate_bins`), with a text legend;
- ``tracking loss``: one ``POINT`` and label per tracking loss (at the last pose before
  it), of the reference once, and of an estimate where the reference kept tracking;
- ``map plan``, ``map walls``, ``map clutter``: the robot's map on the building plan, when
  one was measured, and ``excursions``: the paths outside the tracked room
  (:mod:`exporters.cad.dxf_map`).

DXF stores doubles, so vertices are absolute model coordinates; the base point and the
rest of the metadata (evaluation id, units, frame, site matrix, tolerance, deviation) are
``$CUSTOMPROPERTY`` header entries.
"""

from __future__ import annotations

import functools
import io
import json
from typing import Final

import numpy as np
from ezdxf import colors
from ezdxf import units as dxf_units
from ezdxf.document import Drawing
from ezdxf.filemanagement import new as new_drawing
from ezdxf.layouts.layout import Modelspace
from ezdxf.lldxf.const import DXFError

from exporters.cad.dxf_bulk import BulkPolylines, ColouredPieces
from exporters.cad.dxf_map import add_excursion_layer, add_map_layers
from exporters.cad.georef import add_geodata
from exporters.cad.placement import RGB, Marker, PlacedPath, Placement, place_evaluation
from exporters.colours import scale_words
from exporters.errors import ExportError
from exporters.options import ExportOptions, Units
from loceval.core.arrays import FloatArray
from loceval.evaluation import EstimateResult, EvaluationResult

__all__ = ["export_dxf"]

APPID: Final = "LOCEVAL"
_INSUNITS: Final = {Units.MM: dxf_units.MM, Units.CM: dxf_units.CM, Units.M: dxf_units.M}
_PDMODE_CIRCLE_CROSS: Final = 35  # a point drawn as a circle with an X, visible in any viewer
_INFO_LAYER: Final = "loceval"
_LOSS_LAYER: Final = "tracking loss"
_LOSS_RGB: Final = (158, 158, 158)  # the report's grey tracking-loss bands


def export_dxf(
    result: EvaluationResult, options: ExportOptions, *, placement: Placement | None = None
) -> bytes:
    """Write the evaluation's trajectories as a DXF R2013 drawing.

    Args:
        result: the evaluation.
        options: units, site transform, simplification, ids.
        placement: the placed paths, when the caller computed them for several formats.

    Returns:
        The DXF file (UTF-8 text) as bytes.

    Raises:
        ExportOptionsError: unusable placement options.
        ExportError: ezdxf refused the drawing.
    """
    placement = placement or place_evaluation(result, options)
    try:
        doc, bulk = _drawing(placement)
        add_geodata(doc, placement)  # where a CRS is known
        stream = io.StringIO()
        doc.write(stream)
    except DXFError as err:
        msg = f"ezdxf could not write the DXF drawing ({err}); please report this."
        raise ExportError(msg) from err
    return bulk.splice(stream.getvalue()).encode("utf-8")


def _drawing(placement: Placement) -> tuple[Drawing, BulkPolylines]:
    per_metre = placement.units.per_metre
    doc = new_drawing("R2013", setup=False, units=_INSUNITS[placement.units])
    bulk = BulkPolylines(doc)
    doc.header["$MEASUREMENT"] = 1  # metric
    doc.header["$LUNITS"] = 2  # decimal
    doc.header["$PDMODE"] = _PDMODE_CIRCLE_CROSS
    doc.header["$PROJECTNAME"] = placement.title
    doc.appids.add(APPID)
    _write_metadata(doc, placement)
    msp = doc.modelspace()

    lo, hi = _extents(placement)
    text_h = float(np.clip(np.linalg.norm(hi[:2] - lo[:2]) / 80.0, 0.05 * per_metre, 5 * per_metre))
    doc.header["$PDSIZE"] = 0.6 * text_h

    info = doc.layers.add(_INFO_LAYER, color=colors.WHITE)
    info.description = "loceval: title, units and colour scale of this drawing"
    title = f"{placement.title} - evaluation {placement.evaluation_id} - units {placement.units}"
    msp.add_text(
        title,
        height=text_h,
        dxfattribs={"layer": _INFO_LAYER, "insert": (lo[0], hi[1] + 2 * text_h, lo[2])},
    )

    markers = placement.markers()
    legend_y = float(lo[1]) - 2 * text_h  # legends stack below the drawing
    for path in placement.paths:
        _add_path(doc, msp, bulk, path)
        worst = [m for m in markers if m.path == path.name and m.kind == "worst"]
        layer = f"{path.layer} markers"
        description = f"loceval: greatest errors of {path.name}"
        _add_markers(
            doc,
            msp,
            layer,
            rgb=path.color_rgb,
            description=description,
            markers=worst,
            text_h=text_h,
        )
        if path.estimate is not None:
            corner = (float(lo[0]), legend_y, float(lo[2]))
            legend_y = _add_ate_layer(
                doc, msp, bulk, placement, path, est=path.estimate, corner=corner, text_h=text_h
            )

    losses = [m for m in markers if m.kind == "gap"]
    description = "loceval: tracking loss (no pose), one marker per loss"
    _add_markers(
        doc,
        msp,
        _LOSS_LAYER,
        rgb=_LOSS_RGB,
        description=description,
        markers=losses,
        text_h=text_h,
    )

    add_map_layers(doc, msp, placement)
    add_excursion_layer(doc, msp, placement, text_h)
    center = (lo[:2] + hi[:2]) / 2.0
    height = max(float(hi[1] - lo[1]), float(hi[0] - lo[0]) * 0.6, per_metre) * 1.3
    doc.set_modelspace_vport(height, center=(float(center[0]), float(center[1])))
    # ezdxf copies the model space's extents into $EXTMIN/$EXTMAX when it saves.
    msp.dxf.extmin = tuple(float(v) for v in lo)
    msp.dxf.extmax = tuple(float(v) for v in hi)
    return doc, bulk


def _write_metadata(doc: Drawing, placement: Placement) -> None:
    """Store the placement metadata as ``$CUSTOMPROPERTY`` entries (nested values as JSON)."""
    for key, value in placement.metadata().items():
        if isinstance(value, dict):
            for sub, item in value.items():
                doc.header.custom_vars.append(f"loceval.{sub}", _text(item))
        else:
            doc.header.custom_vars.append(f"loceval.{key}", _text(value))


def _text(value: object) -> str:
    return value if isinstance(value, str) else json.dumps(value)


def _extents(placement: Placement) -> tuple[FloatArray, FloatArray]:
    """Return the drawing's extent: the paths and the building model, when one is given.

    The title goes above it and the legends below it: outside the building's rooms.
    """
    allv = np.concatenate([p.vertices for p in placement.paths])
    if placement.building_bounds is not None:
        allv = np.concatenate([allv, placement.building_bounds])
    return allv.min(axis=0), allv.max(axis=0)


@functools.lru_cache(maxsize=64)
def _nearest_aci(rgb: RGB) -> int:
    """Return the AutoCAD Color Index (1-255) closest to an sRGB colour."""
    target = np.array(rgb, dtype=np.float64)
    table = np.array([colors.aci2rgb(i) for i in range(1, 256)], dtype=np.float64)
    return int(np.argmin(((table - target) ** 2).sum(axis=1))) + 1


def _layer(doc: Drawing, name: str, rgb: RGB, description: str) -> None:
    layer = doc.layers.add(name, color=_nearest_aci(rgb))
    layer.rgb = rgb
    layer.description = description


def _add_path(doc: Drawing, msp: Modelspace, bulk: BulkPolylines, path: PlacedPath) -> None:
    _layer(doc, path.layer, path.color_rgb, f"loceval {path.kind.value}: {path.name}")
    meta = path.metadata()
    ate = meta["ate_translation_m"]
    tags = [
        (1000, f"name={path.name}"),
        (1000, f"kind={path.kind.value}"),
        (1000, f"source={path.source}"),
        (1000, f"poses={path.poses}"),
        (1000, f"max_deviation_m={path.max_deviation_m!r}"),
    ]
    if isinstance(ate, dict):
        tags += [(1000, f"ate_{k}_m={v!r}") for k, v in ate.items() if k != "n"]
    xdata = [(code, value[:255]) for code, value in tags]
    for start, stop in path.pieces():  # one polyline per continuous piece
        if stop - start < 2:
            continue
        polyline = bulk.add(msp, path.vertices[start:stop], {"layer": path.layer})
        polyline.set_xdata(APPID, xdata)


def _add_markers(
    doc: Drawing,
    msp: Modelspace,
    name: str,
    *,
    rgb: RGB,
    description: str,
    markers: list[Marker],
    text_h: float,
) -> None:
    if not markers:
        return
    _layer(doc, name, rgb, description)
    attribs = {"layer": name}
    for marker in markers:
        msp.add_point(marker.position, dxfattribs=attribs)
        if marker.target is not None:
            msp.add_line(marker.position, marker.target, dxfattribs=attribs)
        x, y, z = marker.position
        msp.add_text(
            marker.label,
            height=text_h * 0.6,
            dxfattribs={**attribs, "insert": (x + 0.5 * text_h, y + 0.3 * text_h, z)},
        )


def _add_ate_layer(
    doc: Drawing,
    msp: Modelspace,
    bulk: BulkPolylines,
    placement: Placement,
    path: PlacedPath,
    *,
    est: EstimateResult,
    corner: tuple[float, float, float],
    text_h: float,
) -> float:
    """Draw the estimate cut into ATE-coloured pieces and its legend; return the next legend y."""
    del est  # the runs come from the placement
    name = f"{path.layer} ATE"
    _layer(doc, name, path.color_rgb, f"loceval: {path.name} coloured by ATE")
    bins = placement.ate_bins()
    aci = np.array([_nearest_aci(b.color_rgb) for b in bins], dtype=np.intp)
    true_color = np.array([_int_rgb(b.color_rgb) for b in bins], dtype=np.intp)
    runs = placement.ate_run_arrays(path)  # tens of thousands: as arrays, no object per run
    pieces = ColouredPieces(
        runs.vertices, runs.offsets, aci[runs.bin_index], true_color[runs.bin_index]
    )
    bulk.add_coloured(msp, name, pieces)
    x, y, z = corner
    y -= text_h
    msp.add_text(
        f"{path.name}: ATE translation",
        height=text_h,
        dxfattribs={"layer": name, "insert": (x, y, z)},
    )
    y -= 1.5 * text_h  # what the colours mean: the tolerance in words
    msp.add_text(
        scale_words(placement.result),
        height=0.7 * text_h,
        dxfattribs={"layer": name, "insert": (x, y, z)},
    )
    for k, ate_bin in enumerate(bins, start=1):
        rgb = ate_bin.color_rgb
        msp.add_text(
            ate_bin.label,
            height=text_h,
            dxfattribs={
                "layer": name,
                "insert": (x, y - 1.5 * k * text_h, z),
                "color": _nearest_aci(rgb),
                "true_color": _int_rgb(rgb),
            },
        )
    return y - 1.5 * (len(bins) + 1) * text_h


def _int_rgb(rgb: RGB) -> int:
    return int(colors.rgb2int(rgb))
