"""Rhino export: a .3dm model (version 7) and the 3DM-compatible JSON for Grasshopper.

The .3dm holds, per trajectory, named ``PolylineCurve`` s on the layer
``loceval::<title>::<trajectory>`` (coloured from the palette; one curve per continuous
piece, so a tracking loss is a break, not a straight chord) with user strings (source,
poses, simplification deviation, ATE statistics); for estimates the same path cut into
curves coloured by ATE bin (the report's colours; each named ``<trajectory> ATE <bin>``,
the statistics staying on the path's curves) on the visible sub-layer
``...::<trajectory>::ATE`` and text dots at the greatest errors on ``...::markers``; and
one text dot per tracking loss on ``loceval::<title>::tracking loss``. With a measured map,
its wall cells are point clouds per distance bin on ``...::map walls``; each stretch
outside the tracked room (:mod:`exporters.cad.excursions`) is a purple curve and a text dot
with its label on ``loceval::<title>::excursions``. The model units are the output units;
document user text carries the evaluation metadata and the ATE legend. rhino3dm builds and
writes the model with one placeholder per ATE bin; the tens of thousands of ATE runs are
laid out as object records with NumPy and spliced into its file
(:mod:`exporters.cad.rhino_bulk`).

Rhino stores doubles, so curves are in absolute model coordinates and drop onto the
building model with File > Import. The base point (the reference's bounding-box centre in
model coordinates, rounded to whole metres) is recorded as the EarthAnchorPoint's model
base point.

The JSON (``paths.3dm.json``) carries the same curves encoded by ``CommonObject.Encode()``
(``{version, archive3dm, opennurbs, data}``, what RhinoCommon's ``CommonObject.FromJSON``
and Rhino.Compute decode) with name, colour, layer and units, the ATE runs and the
markers; ``grasshopper/loceval_paths.py`` reads it and bakes it to the same layers. The
runs' curves are encoded once per path (:mod:`exporters.cad.rhino_encode`) for both files.
"""

from __future__ import annotations

import json
import logging
import tempfile
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Final

import numpy as np
import rhino3dm as _rhino3dm

from exporters.cad.dxf_map import placed_cells
from exporters.cad.excursions import EXCURSION_LAYER, EXCURSION_RGB, placed_excursions
from exporters.cad.georef import set_earth_anchor
from exporters.cad.jsondoc import finite_json
from exporters.cad.placement import Marker, PlacedPath, Placement, layer_name, place_evaluation
from exporters.cad.rhino_bulk import RunBlock, splice_runs
from exporters.cad.rhino_encode import (
    PolylineArchives,
    curve_items_json,
    decoded_polyline,
    point_list,
    polyline_archives,
)
from exporters.colours import hex_colour, map_bins, scale_words
from exporters.errors import ExportError
from exporters.options import ExportOptions, Units
from loceval.core.arrays import FloatArray
from loceval.evaluation import EvaluationResult

# rhino3dm's bundled stubs mark writable properties (ModelUnitSystem, Name, LayerIndex, ...)
# read-only and lack overloads the library has; use the module untyped.
rhino3dm: Any = _rhino3dm

logger = logging.getLogger(__name__)

__all__ = [
    "FORMAT",
    "LOSS_LAYER",
    "RHINO_VERSION",
    "evaluation_layer",
    "export_3dm",
    "export_3dm_json",
    "layer_path",
    "write_3dm",
]

RHINO_VERSION: Final = 7
"""The .3dm version written: Rhino 7 and 8 both open it."""
FORMAT: Final = "loceval.paths.3dm.json"
"""The ``format`` field of the JSON document."""
FORMAT_VERSION: Final = 2
"""2: a path is ``curves`` (one per continuous piece), with ``ate`` runs and ``markers``."""
ROOT_LAYER: Final = "loceval"
LOSS_LAYER: Final = "tracking loss"
"""The sub-layer of the evaluation's layer that holds one text dot per tracking loss."""
_LOSS_RGB: Final = (158, 158, 158)
_UNIT_SYSTEMS: Final = {
    Units.MM: rhino3dm.UnitSystem.Millimeters,
    Units.CM: rhino3dm.UnitSystem.Centimeters,
    Units.M: rhino3dm.UnitSystem.Meters,
}


def evaluation_layer(placement: Placement) -> str:
    """Return the evaluation's layer name: its title (the id when the title is empty)."""
    return layer_name(placement.title.strip() or placement.evaluation_id)


def layer_path(placement: Placement, path: PlacedPath) -> str:
    """Return the Rhino layer full path of a trajectory: ``loceval::<title>::<name>``."""
    return f"{ROOT_LAYER}::{evaluation_layer(placement)}::{path.layer}"


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
    data = write_3dm(lambda: _model(placement))
    blocks = [
        RunBlock(_ate_archives(placement, path), runs.bin_index, _placeholders(placement, path))
        for path in placement.paths
        if len(runs := placement.ate_run_arrays(path))
    ]
    spliced = splice_runs(data, blocks) if blocks else data
    if spliced is None:  # this rhino3dm lays out its records otherwise: it writes every run
        logger.warning(
            "rhino3dm %s writes object records in a layout paths.3dm's ATE runs are not "
            "spliced into; it writes each run itself (slower, the same model)",
            getattr(rhino3dm, "__version__", "?"),
        )
        return write_3dm(lambda: _model(placement, bulk=False))
    return spliced


def write_3dm(build: Callable[[], Any]) -> bytes:
    """Build a rhino3dm ``File3dm`` with ``build`` and return it written as a Rhino 7 file.

    Raises:
        ExportError: rhino3dm could not build or write the model.
    """
    try:
        model = build()
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
    "metadata", "ate_bins": [{"label", "color"}], "markers": [{"kind", "path", "label",
    "layer", "position"}], "paths": [{"name", "kind", "source", "layer", "color",
    "color_hex", "poses", "vertices", "pieces", "max_deviation_m", "ate_translation_m",
    "curves", "ate_layer", "ate": [{"bin", "color", "curve"}]}]}``, where each ``curve`` is
    the ``CommonObject.Encode()`` dict of a ``PolylineCurve`` in model coordinates and
    ``units``; ``curves`` holds one per continuous piece (a path breaks at tracking loss).

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
    bins = placement.ate_bins()
    colours = [list(b.color_rgb) for b in bins]
    try:
        for path in placement.paths:
            entry = path.metadata()
            entry["layer"] = layer_path(placement, path)
            entry["curves"] = [curve.Encode() for curve in _pieces(placement, path)]
            entry["ate_layer"] = f"{entry['layer']}::ATE"
            # tens of thousands of runs: encoded with NumPy, as rhino3dm would (rhino_encode)
            entry["ate"] = curve_items_json(
                _ate_archives(placement, path),
                [{"bin": k, "color": colour} for k, colour in enumerate(colours)],
                placement.ate_run_arrays(path).bin_index,
            )
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
        "ate_bins": [
            {"label": b.label, "color": list(b.color_rgb), "beyond": b.beyond} for b in bins
        ],
        "ate_legend": scale_words(placement.result),
        "markers": [
            {
                "kind": m.kind,
                "path": m.path,
                "label": m.label,
                "layer": _marker_layer(placement, m),
                "position": list(m.position),
            }
            for m in placement.markers()
        ],
        "paths": paths,
    }
    return (
        finite_json(document, indent=1, levels=4, what="The Grasshopper document") + "\n"
    ).encode()


def _model(placement: Placement, *, bulk: bool = True) -> Any:  # noqa: ANN401  (untyped)
    """Build the model; with ``bulk``, each ATE layer holds only its runs' placeholders.

    :func:`export_3dm` puts every run in their place once the model is written
    (:mod:`exporters.cad.rhino_bulk`); without ``bulk`` rhino3dm adds every run itself.
    """
    model = rhino3dm.File3dm()
    model.ApplicationName = "loceval"
    settings = model.Settings
    settings.ModelUnitSystem = _UNIT_SYSTEMS[placement.units]
    anchor = settings.EarthAnchorPoint
    earth = set_earth_anchor(anchor, placement, rhino3dm)
    anchor.Name = "loceval base point"
    anchor.Description = (
        "Centre of the reference path, rounded to whole metres, in model units; the "
        f"evaluation frame {placement.frame!r} maps to model coordinates by "
        f"loceval.site_matrix_m. {earth}"
    )
    settings.EarthAnchorPoint = anchor
    for key, value in placement.metadata().items():
        model.Strings[f"loceval.{key}"] = value if isinstance(value, str) else json.dumps(value)

    root = _add_layer(model, ROOT_LAYER, (255, 255, 255), None)
    evaluation = _add_layer(model, evaluation_layer(placement), (255, 255, 255), root)
    bins = placement.ate_bins()
    model.Strings["loceval.ate_bins"] = "; ".join(
        f"{b.label}: {hex_colour(b.color_rgb)}" for b in bins
    )
    model.Strings["loceval.ate_legend"] = scale_words(placement.result)
    markers = placement.markers()
    for path in placement.paths:
        layer = _add_layer(model, path.layer, path.color_rgb, evaluation)
        attributes = rhino3dm.ObjectAttributes()
        attributes.Name = path.name
        attributes.LayerIndex = layer
        attributes.ColorSource = rhino3dm.ObjectColorSource.ColorFromLayer
        for key, value in _user_strings(path).items():
            attributes.SetUserString(key, value)
        for curve in _pieces(placement, path):  # one per continuous piece (the model copies it)
            model.Objects.AddCurve(curve, attributes)
        if path.estimate is None:
            continue
        ate_layer = _add_layer(model, "ATE", path.color_rgb, layer)
        by_bin = [
            _bin_attributes(f"{path.name} ATE", b.label, b.color_rgb, ate_layer) for b in bins
        ]
        _add_ate_runs(model, placement, path, by_bin, bulk=bulk)
        worst = [m for m in markers if m.kind == "worst" and m.path == path.name]
        if worst:
            _add_dots(model, worst, _add_layer(model, "markers", path.color_rgb, layer))
    losses = [m for m in markers if m.kind == "gap"]
    if losses:
        _add_dots(model, losses, _add_layer(model, LOSS_LAYER, _LOSS_RGB, evaluation))
    _add_map(model, placement, evaluation)
    _add_excursions(model, placement, evaluation)
    return model


def _add_ate_runs(
    model: Any,  # noqa: ANN401
    placement: Placement,
    path: PlacedPath,
    by_bin: list[Any],
    *,
    bulk: bool,
) -> None:
    """Add an estimate's ATE runs, or with ``bulk`` the placeholders of its bins."""
    if bulk:  # the first run of each bin, under the id the splice finds it by
        runs = placement.ate_run_arrays(path)
        for index, object_id in _placeholders(placement, path).items():
            attributes = by_bin[int(runs.bin_index[index])]
            attributes.Id = object_id
            vertices = runs.vertices[runs.offsets[index] : runs.offsets[index + 1]]
            model.Objects.AddPolyline(point_list(vertices), attributes)
        return
    for run in placement.ate_runs(path):  # one curve per colour run
        # a PolylineCurve made by the model from the points: no curve object to copy
        model.Objects.AddPolyline(point_list(run.vertices), by_bin[run.bin_index])


def _placeholders(placement: Placement, path: PlacedPath) -> dict[int, uuid.UUID]:
    """Return the index and object id of the run that stands for each bin, once per path."""

    def choose() -> dict[int, uuid.UUID]:
        first = placement.ate_run_arrays(path).first_of_each_bin()
        return {index: uuid.uuid4() for index in first.tolist()}  # one per bin

    return placement.shared(("rhino.placeholders", id(path)), choose)


def _ate_archives(placement: Placement, path: PlacedPath) -> PolylineArchives:
    """Return the curves of a path's ATE runs (the .3dm and its JSON both carry them), once."""

    def build() -> PolylineArchives:
        runs = placement.ate_run_arrays(path)
        return polyline_archives(runs.vertices, runs.offsets)

    return placement.shared(("rhino.ate_archives", id(path)), build)


def _bin_attributes(name: str, label: str, rgb: tuple[int, int, int], layer: int) -> Any:  # noqa: ANN401
    """Return the attributes of an ATE run in the bin ``label``: its name and colour.

    The name carries the bin (``SelName`` picks a bin's runs); no user text, which Rhino
    writes per object as user data (half the file's writing time for 25,000 runs).
    """
    attributes = rhino3dm.ObjectAttributes()
    attributes.Name = f"{name} {label}"
    attributes.LayerIndex = layer
    attributes.ColorSource = rhino3dm.ObjectColorSource.ColorFromObject
    attributes.ObjectColor = (*rgb, 255)
    return attributes


def _add_excursions(model: Any, placement: Placement, parent: int) -> None:  # noqa: ANN401
    """Add ``excursions``: each path outside the tracked room, a curve and a labelled dot."""
    placed = placed_excursions(placement)
    if not placed:
        return
    layer = _add_layer(model, EXCURSION_LAYER, EXCURSION_RGB, parent)
    for path, vertices in placed:  # a few stretches per run
        attributes = rhino3dm.ObjectAttributes()
        attributes.Name = path.label
        attributes.LayerIndex = layer
        attributes.ColorSource = rhino3dm.ObjectColorSource.ColorFromLayer
        for key, value in {"estimate": path.estimate, **path.figures}.items():
            attributes.SetUserString(f"loceval.{key}", str(value))
        points = rhino3dm.Point3dList(len(vertices))
        for x, y, z in vertices.tolist():  # rhino3dm takes points one by one
            points.Add(x, y, z)
        model.Objects.AddCurve(rhino3dm.PolylineCurve(points), attributes)
        model.Objects.AddTextDot(path.label, rhino3dm.Point3d(*vertices[0].tolist()), attributes)


def _add_map(model: Any, placement: Placement, parent: int) -> None:  # noqa: ANN401
    """Add the map's wall cells as one coloured point cloud per distance bin (with a map)."""
    cells = placed_cells(placement)
    found = placement.result.map
    if cells is None or found is None:
        return
    xyz, distance, clutter = cells
    bins = map_bins(found.distance_m, placement.result.config.thresholds_m)
    index = np.searchsorted([b.high_m for b in bins[:-1]], distance, side="left")
    index[clutter] = len(bins)
    layer = _add_layer(model, "map walls", bins[0].color_rgb, parent)
    names = [*(f"map walls {b.label}" for b in bins), "map clutter"]
    colours = [*(b.color_rgb for b in bins), (194, 24, 91)]
    for k, (name, rgb) in enumerate(zip(names, colours, strict=True)):  # one cloud per bin
        chosen = xyz[index == k]
        if not len(chosen):
            continue
        cloud = rhino3dm.PointCloud()
        for x, y, z in chosen.tolist():  # rhino3dm adds points one by one (capped cells)
            cloud.Add(rhino3dm.Point3d(x, y, z))
        attributes = rhino3dm.ObjectAttributes()
        attributes.Name = name
        attributes.LayerIndex = layer
        attributes.ColorSource = rhino3dm.ObjectColorSource.ColorFromObject
        attributes.ObjectColor = (*rgb, 255)
        model.Objects.AddPointCloud(cloud, attributes)


def _add_dots(model: Any, markers: list[Marker], layer: int) -> None:  # noqa: ANN401
    """Add a text dot per marker on the layer at index ``layer``."""
    for marker in markers:  # one per marker (a few dozen at most)
        attributes = rhino3dm.ObjectAttributes()
        attributes.Name = marker.label
        attributes.LayerIndex = layer
        attributes.ColorSource = rhino3dm.ObjectColorSource.ColorFromLayer
        model.Objects.AddTextDot(marker.label, rhino3dm.Point3d(*marker.position), attributes)


def _marker_layer(placement: Placement, marker: Marker) -> str:
    root = f"{ROOT_LAYER}::{evaluation_layer(placement)}"
    if marker.kind == "gap":
        return f"{root}::{LOSS_LAYER}"
    path = next(p for p in placement.paths if p.name == marker.path)
    return f"{root}::{path.layer}::markers"


def _piece_vertices(path: PlacedPath) -> list[FloatArray]:
    """Return the vertices of each piece that is a line (two vertices or more)."""
    return [path.vertices[a:b] for a, b in path.pieces() if b - a >= 2]


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


def _pieces(placement: Placement, path: PlacedPath) -> list[Any]:
    """Return a path's curves, one per continuous piece, with the path's user strings.

    Built once per placement: a run writing both the .3dm and its JSON builds them for the
    first and encodes the same curves for the second (a model keeps copies of its curves).
    """

    def build() -> list[Any]:
        strings = _user_strings(path)  # once per path: its statistics cover every pose
        return [_curve(v, strings) for v in _piece_vertices(path)]

    return list(placement.shared(("rhino.pieces", id(path)), build))


def _curve(vertices: FloatArray, user_strings: Mapping[str, str]) -> Any:  # noqa: ANN401
    """A polyline curve through ``vertices`` carrying its path's user strings."""
    curve = decoded_polyline(vertices)
    for key, value in user_strings.items():
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
