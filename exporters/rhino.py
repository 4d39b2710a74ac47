"""Rhino export: a .3dm model (version 7) and the 3DM-compatible JSON for Grasshopper.

The .3dm holds, per trajectory, a named ``PolylineCurve`` on the layer
``loceval::<evaluation>::<trajectory>`` (coloured from the palette) with user strings
(source, poses, simplification deviation, ATE statistics), and for estimates an
ATE-coloured point cloud on the hidden sub-layer ``...::<trajectory>::ATE``. The model
units are the output units; document user text carries the evaluation metadata.

Rhino stores doubles, so curves are in absolute model coordinates and drop onto the
building model with File > Import. The base point (the reference's bounding-box centre in
model coordinates, rounded to whole metres) is recorded as the EarthAnchorPoint's model
base point.

The JSON (``paths.3dm.json``) carries the same curves encoded by ``CommonObject.Encode()``
(``{version, archive3dm, opennurbs, data}``, what RhinoCommon's ``CommonObject.FromJSON``
and Rhino.Compute decode) with name, colour, layer and units; ``grasshopper/loceval_paths.py``
reads it.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any, Final

import numpy as np
import rhino3dm as _rhino3dm

from exporters.errors import ExportError
from exporters.options import ExportOptions, Units
from exporters.placement import (
    PlacedPath,
    Placement,
    ate_bins,
    layer_name,
    place_evaluation,
)
from loceval._typing import FloatArray
from loceval.evaluation import EvaluationResult

# rhino3dm's bundled stubs mark writable properties (ModelUnitSystem, Name, LayerIndex, ...)
# read-only and lack overloads the library has; use the module untyped.
rhino3dm: Any = _rhino3dm

__all__ = ["FORMAT", "RHINO_VERSION", "export_3dm", "export_3dm_json", "layer_path"]

RHINO_VERSION: Final = 7
"""The .3dm version written: Rhino 7 and 8 both open it."""
FORMAT: Final = "loceval.paths.3dm.json"
"""The ``format`` field of the JSON document."""
FORMAT_VERSION: Final = 1
ROOT_LAYER: Final = "loceval"
_UNIT_SYSTEMS: Final = {
    Units.MM: rhino3dm.UnitSystem.Millimeters,
    Units.CM: rhino3dm.UnitSystem.Centimeters,
    Units.M: rhino3dm.UnitSystem.Meters,
}


def layer_path(placement: Placement, path: PlacedPath) -> str:
    """Return the Rhino layer full path of a trajectory: ``loceval::<evaluation>::<name>``."""
    return f"{ROOT_LAYER}::{layer_name(placement.evaluation_id)}::{path.layer}"


def export_3dm(
    result: EvaluationResult, options: ExportOptions, *, placement: Placement | None = None
) -> bytes:
    """Write the evaluation's trajectories as a Rhino 7 .3dm model.

    Args:
        result: the evaluation.
        options: units, site transform, simplification, ids.
        placement: the placed paths, when the caller computed them for several formats.

    Returns:
        The .3dm file.

    Raises:
        ExportOptionsError: unusable placement options.
        ExportError: rhino3dm could not build or write the model.
    """
    placement = placement or place_evaluation(result, options)
    try:
        model = _model(placement)
        with tempfile.TemporaryDirectory(prefix="loceval-3dm-") as tmp:
            target = Path(tmp) / "paths.3dm"
            if not model.Write(str(target), RHINO_VERSION):
                msg = "rhino3dm could not write the .3dm model; please report this."
                raise ExportError(msg)
            return target.read_bytes()
    except (RuntimeError, OSError) as err:
        msg = f"rhino3dm could not build the .3dm model ({err}); please report this."
        raise ExportError(msg) from err


def export_3dm_json(
    result: EvaluationResult, options: ExportOptions, *, placement: Placement | None = None
) -> bytes:
    """Write the 3DM-compatible JSON document that the Grasshopper script reads.

    Layout: ``{"format", "format_version", "units", "rhino_unit_system", "base_point",
    "metadata", "paths": [{"name", "kind", "source", "layer", "color", "color_hex", "poses",
    "vertices", "max_deviation_m", "ate_translation_m", "curve"}]}``, where ``curve`` is the
    ``CommonObject.Encode()`` dict of a ``PolylineCurve`` in model coordinates and ``units``.

    Args:
        result: the evaluation.
        options: units, site transform, simplification, ids.
        placement: the placed paths, when the caller computed them for several formats.

    Returns:
        The JSON document as UTF-8 bytes.

    Raises:
        ExportOptionsError: unusable placement options.
        ExportError: rhino3dm could not encode a curve.
    """
    placement = placement or place_evaluation(result, options)
    paths = []
    try:
        for path in placement.paths:
            entry = path.metadata()
            entry["layer"] = layer_path(placement, path)
            entry["curve"] = _curve(path).Encode()
            paths.append(entry)
    except RuntimeError as err:
        msg = f"rhino3dm could not encode a curve ({err}); please report this."
        raise ExportError(msg) from err
    document = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "units": placement.units.value,
        "rhino_unit_system": _UNIT_SYSTEMS[placement.units].name,
        "base_point": placement.base_point.tolist(),
        "metadata": placement.metadata(),
        "paths": paths,
    }
    return (json.dumps(document, indent=1, allow_nan=False) + "\n").encode("utf-8")


def _model(placement: Placement) -> Any:  # noqa: ANN401  (rhino3dm is untyped here)
    model = rhino3dm.File3dm()
    model.ApplicationName = "loceval"
    settings = model.Settings
    settings.ModelUnitSystem = _UNIT_SYSTEMS[placement.units]
    anchor = settings.EarthAnchorPoint
    anchor.ModelBasePoint = rhino3dm.Point3d(*placement.base_point.tolist())
    anchor.Name = "loceval base point"
    anchor.Description = (
        "Centre of the reference path, rounded to whole metres, in model units; the "
        f"evaluation frame {placement.frame!r} maps to model coordinates by "
        "loceval.site_matrix_m."
    )
    settings.EarthAnchorPoint = anchor
    for key, value in placement.metadata().items():
        model.Strings[f"loceval.{key}"] = value if isinstance(value, str) else json.dumps(value)

    root = _add_layer(model, ROOT_LAYER, (255, 255, 255), None)
    evaluation = _add_layer(model, layer_name(placement.evaluation_id), (255, 255, 255), root)
    bins = ate_bins(placement.result.config.thresholds_m)
    for path in placement.paths:
        layer = _add_layer(model, path.layer, path.color_rgb, evaluation)
        attributes = rhino3dm.ObjectAttributes()
        attributes.Name = path.name
        attributes.LayerIndex = layer
        attributes.ColorSource = rhino3dm.ObjectColorSource.ColorFromLayer
        curve = _curve(path)
        for key, value in _user_strings(path).items():
            attributes.SetUserString(key, value)
        model.Objects.AddCurve(curve, attributes)
        if path.errors_m is None:
            continue
        ate_layer = _add_layer(model, "ATE", path.color_rgb, layer, visible=False)
        edges = np.array([b.high_m for b in bins[:-1]])
        which = np.searchsorted(edges, path.errors_m, side="left")
        cloud = rhino3dm.PointCloud()
        cloud.AddRange(_points(path.vertices), [(*bins[k].color_rgb, 255) for k in which.tolist()])
        cloud_attributes = rhino3dm.ObjectAttributes()
        cloud_attributes.Name = f"{path.name} ATE"
        cloud_attributes.LayerIndex = ate_layer
        cloud_attributes.SetUserString(
            "loceval.ate_bins", "; ".join(f"{b.label}: {_hex(b.color_rgb)}" for b in bins)
        )
        model.Objects.AddPointCloud(cloud, cloud_attributes)
    return model


def _add_layer(
    model: Any,  # noqa: ANN401
    name: str,
    rgb: tuple[int, int, int],
    parent: int | None,
    *,
    visible: bool = True,
) -> int:
    """Add a layer below the layer at index ``parent`` and return its index."""
    layer = rhino3dm.Layer()
    layer.Name = name
    layer.Color = (*rgb, 255)
    layer.Visible = visible
    if parent is not None:
        layer.ParentLayerId = model.Layers[parent].Id
    index: int = model.Layers.Add(layer)
    return index


def _points(vertices: FloatArray) -> list[Any]:
    return [rhino3dm.Point3d(x, y, z) for x, y, z in vertices.tolist()]


def _curve(path: PlacedPath) -> Any:  # noqa: ANN401
    points = rhino3dm.Point3dList(len(path.vertices))
    for x, y, z in path.vertices.tolist():  # rhino3dm takes points one by one
        points.Add(x, y, z)
    curve = rhino3dm.PolylineCurve(points)
    for key, value in _user_strings(path).items():
        curve.SetUserString(key, value)
    return curve


def _user_strings(path: PlacedPath) -> dict[str, str]:
    strings = {
        "loceval.name": path.name,
        "loceval.kind": path.kind.value,
        "loceval.source": path.source,
        "loceval.poses": str(path.poses),
        "loceval.max_deviation_m": repr(path.max_deviation_m),
    }
    if path.estimate is not None:
        stats = path.estimate.ate_translation.stats.to_dict()
        strings.update({f"loceval.ate_{k}_m": repr(v) for k, v in stats.items() if k != "n"})
    return strings


def _hex(rgb: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*rgb)
