"""Rhino export of an evaluation against control points: ``paths.3dm`` and ``paths.3dm.json``.

The same content as the DXF (:mod:`exporters.cad.dxf_points`), on layers below
``loceval::<title>`` (as :mod:`exporters.cad.rhino` names them):

- ``control points``: a point object per surveyed point, named by its id, and a text dot
  with the id;
- ``<estimate> measured``: a point object per visit at the measured (aligned median)
  position, named by the error label;
- ``<estimate> errors``: a line from the surveyed point to the measured position per visit
  and a text dot with its label (``P01 12.3 mm``); visits that fixed the alignment are grey.

Absolute model coordinates in the output units, the site transform applied; the base
point (the points' bounding-box centre rounded to whole metres) is the EarthAnchorPoint's
model base point. The JSON follows :func:`exporters.cad.rhino.export_3dm_json`'s layout
(format version 2): the error lines are ``paths`` (an encoded two-point ``PolylineCurve``
per visit, so the Grasshopper script and Hops read them as trajectory pieces; ``poses``
counts the visits, one measured position each),
the ids and labels are ``markers`` with a ``color``, and the point objects are the extra
list ``points`` (``{"kind", "label", "layer", "color", "position"}``), which
``grasshopper/loceval_paths.py`` reads.
"""

from __future__ import annotations

import json
from typing import Any

import rhino3dm as _rhino3dm

from exporters.cad.jsondoc import finite_json
from exporters.cad.points_placement import (
    POINTS_LAYER,
    POINTS_RGB,
    PlacedControlPoints,
    place_control_points,
)
from exporters.cad.rhino import FORMAT, FORMAT_VERSION, ROOT_LAYER, write_3dm
from exporters.colours import RGB, layer_name
from exporters.errors import ExportError
from exporters.options import ExportOptions, Units
from loceval.checkpoint_evaluation import CheckpointEvaluation

rhino3dm: Any = _rhino3dm  # untyped, as in exporters.cad.rhino

__all__ = ["export_points_3dm", "export_points_3dm_json", "points_layer_root"]

_UNIT_SYSTEMS = {
    Units.MM: rhino3dm.UnitSystem.Millimeters,
    Units.CM: rhino3dm.UnitSystem.Centimeters,
    Units.M: rhino3dm.UnitSystem.Meters,
}

Item = tuple[str, str, str, RGB, tuple[float, ...]]
"""(kind, label, layer full path, rgb, position or start + end) of one object."""


def points_layer_root(placed: PlacedControlPoints) -> str:
    """Return the evaluation's layer path: ``loceval::<title>`` (the id without a title)."""
    return f"{ROOT_LAYER}::{layer_name(placed.title.strip() or placed.evaluation_id)}"


def _items(placed: PlacedControlPoints) -> list[Item]:
    """Return every object of the drawing, in the DXF's order."""
    root = points_layer_root(placed)
    items: list[Item] = []
    layer = f"{root}::{POINTS_LAYER}"
    for pid, xyz in zip(placed.ids, placed.points.tolist(), strict=True):  # per point
        items.append(("control point", pid, layer, POINTS_RGB, tuple(xyz)))
    for est in placed.estimates:
        measured, errors = f"{root}::{est.measured_layer}", f"{root}::{est.errors_layer}"
        rows = zip(
            est.labels, est.colours(), est.surveyed.tolist(), est.measured.tolist(), strict=True
        )
        for label, rgb, start, end in rows:  # one group per visit
            items.append(("measured", label, measured, rgb, tuple(end)))
            items.append(("error", label, errors, rgb, (*start, *end)))
    return items


def export_points_3dm(evaluation: CheckpointEvaluation, options: ExportOptions) -> bytes:
    """Write the control points, measured positions and error lines as a Rhino 7 .3dm.

    Raises:
        ExportError: rhino3dm could not build or write the model.
    """
    placed = place_control_points(evaluation, options)
    return write_3dm(lambda: _model(placed))


def export_points_3dm_json(evaluation: CheckpointEvaluation, options: ExportOptions) -> bytes:
    """Write the 3DM-compatible JSON of the control points (read by the Grasshopper script).

    Raises:
        ExportError: rhino3dm could not encode a line.
    """
    placed = place_control_points(evaluation, options)
    root = points_layer_root(placed)
    items = _items(placed)
    try:
        paths = [
            {
                "name": est.errors_layer,
                "kind": "errors",
                "source": placed.source,
                "layer": f"{root}::{est.errors_layer}",
                "color": list(est.color_rgb),
                "color_hex": "#{:02x}{:02x}{:02x}".format(*est.color_rgb),
                "labels": list(est.labels),
                "poses": len(est.labels),
                "vertices": 2 * len(est.labels),
                "max_deviation_m": 0.0,
                "curves": [
                    _polyline(item[4]).Encode()
                    for item in items
                    if item[0] == "error" and item[2] == f"{root}::{est.errors_layer}"
                ],
                "ate_layer": f"{root}::{est.errors_layer}",
                "ate": [],
            }
            for est in placed.estimates
        ]
    except RuntimeError as err:
        msg = f"rhino3dm could not encode a line ({err}); please report this."
        raise ExportError(msg) from err
    markers = [
        {"kind": kind, "path": "", "label": label, "layer": layer, "color": list(rgb),
         "position": list(xyz[-3:])}
        for kind, label, layer, rgb, xyz in items
        if kind != "measured"
    ]  # fmt: skip
    points = [
        {"kind": kind, "label": label, "layer": layer, "color": list(rgb), "position": list(xyz)}
        for kind, label, layer, rgb, xyz in items
        if kind != "error"
    ]
    document = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "units": placed.units.value,
        "rhino_unit_system": _UNIT_SYSTEMS[placed.units].name,
        "base_point": placed.base_point.tolist(),
        "metadata": placed.metadata,
        "ate_bins": [],
        "markers": markers,
        "points": points,
        "paths": paths,
    }
    return (
        finite_json(document, indent=1, levels=4, what="The Grasshopper document") + "\n"
    ).encode()


def _polyline(start_end: tuple[float, ...]) -> Any:  # noqa: ANN401
    """Return a two-point PolylineCurve (what every ``curves`` entry of the JSON is)."""
    points = rhino3dm.Point3dList(2)
    points.Add(*start_end[:3])
    points.Add(*start_end[3:])
    return rhino3dm.PolylineCurve(points)


def _line(start_end: tuple[float, ...]) -> Any:  # noqa: ANN401  (rhino3dm is untyped here)
    return rhino3dm.LineCurve(rhino3dm.Point3d(*start_end[:3]), rhino3dm.Point3d(*start_end[3:]))


def _model(placed: PlacedControlPoints) -> Any:  # noqa: ANN401
    model = rhino3dm.File3dm()
    model.ApplicationName = "loceval"
    settings = model.Settings
    settings.ModelUnitSystem = _UNIT_SYSTEMS[placed.units]
    anchor = settings.EarthAnchorPoint
    anchor.ModelBasePoint = rhino3dm.Point3d(*placed.base_point.tolist())
    anchor.Name = "loceval base point"
    anchor.Description = (
        "Centre of the control points, rounded to whole metres, in model units; the "
        "building frame maps to model coordinates by loceval.site_matrix_m."
    )
    settings.EarthAnchorPoint = anchor
    for key, value in placed.metadata.items():
        model.Strings[f"loceval.{key}"] = value if isinstance(value, str) else json.dumps(value)
    layers: dict[str, int] = {}
    colours = {f"{points_layer_root(placed)}::{POINTS_LAYER}": POINTS_RGB}
    for est in placed.estimates:
        for name in (est.measured_layer, est.errors_layer):
            colours[f"{points_layer_root(placed)}::{name}"] = est.color_rgb
    for kind, label, layer, rgb, xyz in _items(placed):  # one object (two for ids) per item
        attributes = rhino3dm.ObjectAttributes()
        attributes.Name = label
        attributes.LayerIndex = _layer(model, layers, layer, colours.get(layer, POINTS_RGB))
        attributes.ColorSource = rhino3dm.ObjectColorSource.ColorFromObject
        attributes.ObjectColor = (*rgb, 255)
        attributes.SetUserString("loceval.kind", kind)
        if kind == "error":
            model.Objects.AddCurve(_line(xyz), attributes)
            model.Objects.AddTextDot(label, rhino3dm.Point3d(*xyz[3:]), attributes)
            continue
        model.Objects.AddPoint(rhino3dm.Point3d(*xyz), attributes)
        if kind == "control point":
            model.Objects.AddTextDot(label, rhino3dm.Point3d(*xyz), attributes)
    return model


def _layer(model: Any, layers: dict[str, int], full_path: str, rgb: RGB) -> int:  # noqa: ANN401
    """Return the index of the layer ``a::b::c``, adding it and its parents if missing."""
    if full_path in layers:
        return layers[full_path]
    parent, _, name = full_path.rpartition("::")
    layer = rhino3dm.Layer()
    layer.Name = name
    layer.Color = (*rgb, 255)
    if parent:
        layer.ParentLayerId = model.Layers[_layer(model, layers, parent, POINTS_RGB)].Id
    layers[full_path] = model.Layers.Add(layer)
    return layers[full_path]
