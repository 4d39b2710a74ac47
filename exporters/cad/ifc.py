"""IFC4 export (``paths.ifc``): one ``IfcAnnotation`` per trajectory, for Revit, ArchiCAD, Solibri.

Each trajectory becomes an ``IfcAnnotation`` (``ObjectType`` ``"trajectory"``) named after
it, contained in one ``IfcSite`` of one ``IfcProject``. Its ``Curve3D`` representation holds
one ``IfcIndexedPolyCurve`` per continuous piece: the placed path (the same vertices as the
DXF) cut where the trajectory has no pose for longer than the evaluation's ``max_gap_s``
(:func:`tracking_losses`). Each curve is styled in the path's palette colour. A property
set ``Loceval_Path`` holds its kind, source, vertex counts, ATE/RPE statistics and verdict;
the project's ``Loceval_Evaluation`` holds the file-level metadata. Each estimate also has
an ``ATE`` annotation (``ObjectType`` ``"ATE"``): its path cut into runs coloured by the one
error scale (anchored to the tolerance when there is one), the legend in ``Loceval_ATE``.
The greatest errors
and the tracking losses are ``IfcAnnotation`` points (``ObjectType`` ``"greatest error"``
or ``"tracking loss"``) whose name is their label; a greatest error also has the line to
the reference pose its error is measured to. A measured map adds the plan's walls
(``map plan``, with the map's figures in ``Loceval_Map``) and the wall cells as point
clouds per distance bin (``map walls``); each stretch outside the tracked room is an
``excursion`` curve (:mod:`exporters.cad.ifc_map`).

Length units are the output units (``IfcSIUnit`` metre with prefix MILLI, CENTI or none).

Georeferencing: with a coordinate reference system (``options.crs``, e.g. ``EPSG:25832``)
the vertices stay in the evaluation frame (scaled to the output units) and an
``IfcMapConversion`` to an ``IfcProjectedCRS`` (map unit metre) carries the site
transform: ``Eastings``, ``Northings``, ``OrthogonalHeight`` are its translation in
metres, ``XAxisAbscissa = cos(yaw)`` and ``XAxisOrdinate = sin(yaw)`` with the yaw
counter-clockwise from the map's x axis (easting), and ``Scale`` = site scale / units per
metre. Applying the conversion,

    E = Eastings + Scale * (x cos(yaw) - y sin(yaw)),
    N = Northings + Scale * (x sin(yaw) + y cos(yaw)),
    H = OrthogonalHeight + Scale * z,

gives the DXF's model coordinates in metres. Revit's "angle to true north" is the same
angle with the opposite sign only when the map's grid north is true north (it is measured
clockwise). Without a CRS the vertices are the DXF's model coordinates, as they are.
"""

from __future__ import annotations

import json
import math
import re
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import ifcopenshell
import ifcopenshell.guid
import numpy as np

from exporters.cad.building import georeferenced_options
from exporters.cad.ifc_map import add_annotation, add_excursions, add_map
from exporters.cad.ifc_text import PLACEHOLDER_TEXT, Prototype, TextRuns, write_runs
from exporters.cad.placement import Marker, PlacedPath, Placement, place_evaluation
from exporters.colours import hex_colour, scale_words
from exporters.errors import ExportError, ExportOptionsError
from exporters.options import ExportOptions, Units
from loceval.core.arrays import FloatArray
from loceval.core.geometry import SimilarityTransform
from loceval.evaluation import EstimateResult, EvaluationResult
from loceval.metrics.pose_errors import ErrorSeries

__all__ = [
    "ATE_TYPE",
    "MARKER_TYPES",
    "TRAJECTORY_TYPE",
    "Georeference",
    "export_ifc",
    "georeference",
]

TRAJECTORY_TYPE: Final = "trajectory"
"""``ObjectType`` of the annotation of a trajectory."""
ATE_TYPE: Final = "ATE"
"""``ObjectType`` of an estimate's path coloured by its error (the one colour scale)."""
MARKER_TYPES: Final = {"worst": "greatest error", "gap": "tracking loss"}
"""``ObjectType`` of the point annotations, by marker kind."""
_PREFIX: Final = {Units.MM: "MILLI", Units.CM: "CENTI", Units.M: None}
_NS_PER_S: Final = 1_000_000_000
_GUID_NAMESPACE: Final = uuid.UUID("5f0c7c57-6d1e-4c1b-9a43-7b1f0f1c1e15")
_YAW_ONLY_ATOL: Final = 1e-9
_PLACEHOLDER: Final = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
_PLACEHOLDER_TEXT: Final = PLACEHOLDER_TEXT
_PLACEHOLDER_LINE: Final = re.compile(
    r"^#(\d+)=IFCCARTESIANPOINTLIST3D\(" + re.escape(_PLACEHOLDER_TEXT), re.MULTILINE
)


@dataclass(frozen=True, slots=True, eq=False)
class Georeference:
    """How the IFC places its coordinates (see the module docstring).

    Attributes:
        crs: the projected CRS name, or None (then the vertices are model coordinates).
        site: evaluation frame (metres) -> model coordinates (metres).
    """

    crs: str | None
    site: SimilarityTransform

    def __post_init__(self) -> None:
        """Check that a site with a CRS only turns about Z.

        Raises:
            ExportOptionsError: a CRS with a site transform that tilts the evaluation frame.
        """
        r = self.site.rotation
        tilted = not np.allclose(r[2], [0.0, 0.0, 1.0], atol=_YAW_ONLY_ATOL)
        if self.crs is not None and tilted:
            msg = (
                f"The site transform tilts the evaluation frame (rotation row z = "
                f"{r[2].tolist()!r}), which a map conversion to {self.crs!r} cannot express; "
                f"give a site transform that only turns about the vertical axis."
            )
            raise ExportOptionsError(msg, option="site")

    @property
    def yaw_rad(self) -> float:
        """Return the site's rotation about Z, counter-clockwise from the map's x axis."""
        r = self.site.rotation
        return math.atan2(float(r[1, 0]), float(r[0, 0]))


def georeference(options: ExportOptions) -> Georeference:
    """Return the CRS and site transform the IFC is placed with.

    They are the options' own, or else those of an IFC building's map conversion.

    Raises:
        ExportOptionsError: a CRS with a site transform that tilts the evaluation frame,
            or an IFC building that cannot be read.
    """
    options = georeferenced_options(options)
    return Georeference(options.crs, options.site)


def export_ifc(
    result: EvaluationResult, options: ExportOptions, *, placement: Placement | None = None
) -> bytes:
    """Write the evaluation's trajectories as an IFC4 file.

    Args:
        result: the evaluation.
        options: units, site transform, CRS, simplification, ids.
        placement: the placed paths, when the caller computed them for several formats.

    Returns:
        The IFC file (ISO 10303-21 text) as bytes.

    Raises:
        ExportOptionsError: unusable placement options.
        ExportError: ifcopenshell refused the model.
    """
    options = georeferenced_options(options)  # read an IFC building's georeference once
    geo = georeference(options)
    same_site = placement is not None and np.allclose(
        placement.site.as_matrix(), geo.site.as_matrix(), rtol=0.0, atol=1e-12
    )
    if placement is None or not same_site:
        placement = place_evaluation(result, options)
    try:
        builder = IfcBuilder(placement, geo)
        text = builder.build().to_string()  # type: ignore[no-untyped-call]
    except (RuntimeError, TypeError, ValueError) as err:
        msg = f"ifcopenshell could not write the IFC model ({err}); please report this."
        raise ExportError(msg) from err
    return builder.finish(text).encode("utf-8")


class IfcBuilder:
    """Builds the IFC entities of one placement.

    ifcopenshell spends about 80 us per coordinate serializing a point list (16 s for
    100,000 poses of two paths), so each path's ``IfcCartesianPointList3D`` is created with
    a two-point placeholder and its coordinates are written into the text afterwards
    (:meth:`splice_point_lists`), fixed-point with 6 decimals (1 nm in millimetres, 1 um
    in metres), in bulk. An estimate's ATE runs (25,000 for 50,000 poses) are created by
    ifcopenshell once per bin and written as STEP text for the rest
    (:mod:`exporters.cad.ifc_text`), unless ``text_runs`` is False.
    """

    def __init__(self, placement: Placement, geo: Georeference, *, text_runs: bool = True) -> None:
        self.placement = placement
        self.geo = geo
        self.f = ifcopenshell.file(schema="IFC4")
        # with a CRS the file keeps evaluation-frame coordinates: model -> evaluation frame
        self.to_local = geo.site.inverse() if geo.crs is not None else None
        self.point_lists: dict[int, FloatArray] = {}  # entity id -> (M, 3) coordinates
        self.text_runs = text_runs
        self.run_groups: list[TextRuns] = []  # the ATE runs written as text, per annotation

    def finish(self, text: str) -> str:
        """Return the file's text: the ATE runs added and every point list's coordinates."""
        if not self.run_groups:
            return self.splice_point_lists(text)
        text, runs = write_runs(text, self.run_groups, int(self.f.get_max_id()) + 1)
        text = self.splice_point_lists(text)
        end = text.rindex("ENDSEC;")  # the DATA section's end
        return text[:end] + runs + text[end:]

    def point_list(self, points: FloatArray) -> ifcopenshell.entity_instance:
        """Return an ``IfcCartesianPointList3D`` placeholder for (M, 3) coordinates."""
        placeholder = self.f.create_entity("IfcCartesianPointList3D", CoordList=_PLACEHOLDER)
        self.point_lists[int(placeholder.id())] = points
        return placeholder

    def splice_point_lists(self, text: str) -> str:
        """Write each point list's coordinates over its placeholder in the STEP text."""

        def coordinates(match: re.Match[str]) -> str:
            points = self.point_lists[int(match.group(1))]
            flat = np.ascontiguousarray(points, dtype=np.float64).reshape(-1).tolist()
            body = ",".join(["(%.6f,%.6f,%.6f)"] * len(points)) % tuple(flat)
            return f"{match.group(0)[: -len(_PLACEHOLDER_TEXT)]}({body})"

        return _PLACEHOLDER_LINE.sub(coordinates, text)

    def guid(self, key: str) -> str:
        """Return a GlobalId stable for the same evaluation and object."""
        name = f"{self.placement.evaluation_id}/{key}"
        return str(ifcopenshell.guid.compress(uuid.uuid5(_GUID_NAMESPACE, name).hex))

    def coords(self, model: FloatArray) -> FloatArray:
        """Map (N, 3) model coordinates in output units to the file's coordinates."""
        if self.to_local is None:
            return model
        per_metre = self.placement.units.per_metre
        out: FloatArray = self.to_local.apply_positions(model / per_metre) * per_metre
        return out

    def build(self) -> ifcopenshell.file:
        f, placement = self.f, self.placement
        origin = f.createIfcAxis2Placement3D(f.createIfcCartesianPoint((0.0, 0.0, 0.0)))
        context = f.create_entity(
            "IfcGeometricRepresentationContext",
            ContextIdentifier="Model",
            ContextType="Model",
            CoordinateSpaceDimension=3,
            Precision=1e-5,
            WorldCoordinateSystem=origin,
        )
        self.annotation_ctx = f.create_entity(
            "IfcGeometricRepresentationSubContext",
            ContextIdentifier="Annotation",
            ContextType="Model",
            ParentContext=context,
            TargetView="MODEL_VIEW",
        )
        length = f.create_entity(
            "IfcSIUnit", UnitType="LENGTHUNIT", Prefix=_PREFIX[placement.units], Name="METRE"
        )
        angle = f.create_entity("IfcSIUnit", UnitType="PLANEANGLEUNIT", Name="RADIAN")
        project = f.create_entity(
            "IfcProject",
            GlobalId=self.guid("project"),
            Name=placement.title,
            Description=f"loceval evaluation {placement.evaluation_id}",
            RepresentationContexts=[context],
            UnitsInContext=f.createIfcUnitAssignment([length, angle]),
        )
        if self.geo.crs is not None:
            self._map_conversion(context)
        self.site_placement = f.createIfcLocalPlacement(None, origin)
        site = f.create_entity(
            "IfcSite",
            GlobalId=self.guid("site"),
            Name="loceval site",
            ObjectPlacement=self.site_placement,
            CompositionType="ELEMENT",
        )
        f.create_entity(
            "IfcRelAggregates",
            GlobalId=self.guid("project/site"),
            RelatingObject=project,
            RelatedObjects=[site],
        )
        self.pset(project, "Loceval_Evaluation", _evaluation_properties(placement))
        elements = []
        markers = placement.markers()
        for path in placement.paths:
            elements.append(self._path(path))
            if path.estimate is not None and len(placement.ate_run_arrays(path)):
                elements.append(self._ate(path))
            elements += [self._marker(m, k) for k, m in enumerate(markers) if m.path == path.name]
        elements += add_map(self) + add_excursions(self)
        f.create_entity(
            "IfcRelContainedInSpatialStructure",
            GlobalId=self.guid("site/contents"),
            RelatedElements=elements,
            RelatingStructure=site,
        )
        return f

    def _map_conversion(self, context: ifcopenshell.entity_instance) -> None:
        f, geo = self.f, self.geo
        metre = f.create_entity("IfcSIUnit", UnitType="LENGTHUNIT", Name="METRE")
        crs = f.create_entity(
            "IfcProjectedCRS",
            Name=geo.crs,
            Description="projected CRS the site transform places the evaluation in",
            MapUnit=metre,
        )
        east, north, height = (float(v) for v in geo.site.translation)
        f.create_entity(
            "IfcMapConversion",
            SourceCRS=context,
            TargetCRS=crs,
            Eastings=east,
            Northings=north,
            OrthogonalHeight=height,
            XAxisAbscissa=math.cos(geo.yaw_rad),
            XAxisOrdinate=math.sin(geo.yaw_rad),
            Scale=float(geo.site.scale) / self.placement.units.per_metre,
        )

    def local_placement(self) -> ifcopenshell.entity_instance:
        """Return a new ``IfcLocalPlacement`` at the site's origin (one per product)."""
        f = self.f
        axis = f.createIfcAxis2Placement3D(f.createIfcCartesianPoint((0.0, 0.0, 0.0)))
        return f.createIfcLocalPlacement(self.site_placement, axis)

    def style(
        self, item: ifcopenshell.entity_instance, name: str, rgb: Sequence[int]
    ) -> ifcopenshell.entity_instance:
        """Give a representation item a named curve colour (0-255 sRGB); return the styling."""
        f = self.f
        r, g, b = (c / 255.0 for c in rgb)
        colour = f.create_entity("IfcColourRgb", Name=name, Red=r, Green=g, Blue=b)
        style = f.create_entity(
            "IfcCurveStyle", Name=name, CurveColour=colour, ModelOrDraughting=True
        )
        return f.create_entity("IfcStyledItem", Item=item, Styles=[style], Name=name)

    def _path(self, path: PlacedPath) -> ifcopenshell.entity_instance:
        f = self.f
        # the placement's pieces: the same breaks at tracking loss as every other CAD file
        pieces = [slice(a, b) for a, b in path.pieces()]
        vertices = self.coords(path.vertices)
        items = []
        for piece in pieces:
            points = vertices[piece]
            if len(points) >= 2:
                point_list = self.point_list(points)
                items.append(
                    f.create_entity("IfcIndexedPolyCurve", Points=point_list, SelfIntersect=False)
                )
            else:  # a lone pose between two tracking losses
                items.append(f.createIfcCartesianPoint(tuple(points[0].tolist())))
        for item in items:
            self.style(item, path.layer, path.color_rgb)
        curves_only = all(len(vertices[p]) >= 2 for p in pieces)
        annotation = add_annotation(
            self,
            name=path.name,
            kind=TRAJECTORY_TYPE,
            description=f"loceval {path.kind.value}: {path.source}",
            representation=("Curve3D" if curves_only else "GeometricSet", items),
            key=f"path/{path.name}",
        )
        properties = _path_properties(path, pieces=len(pieces))
        self.pset(annotation, "Loceval_Path", properties)
        return annotation

    def _ate(self, path: PlacedPath) -> ifcopenshell.entity_instance:
        """The estimate cut into runs of one ATE bin, each curve in its bin's colour."""
        f, placement = self.f, self.placement
        bins = placement.ate_bins()
        items = []
        runs = placement.ate_run_arrays(path)
        # ifcopenshell makes the first run of each bin (every run without text runs)
        made = runs.first_of_each_bin() if self.text_runs else np.arange(len(runs))
        group = TextRuns(representation=0, order=[None] * len(runs))
        for index in made.tolist():  # a few: one per bin
            vertices = runs.vertices[runs.offsets[index] : runs.offsets[index + 1]]
            point_list = self.point_list(self.coords(vertices))
            curve = f.create_entity("IfcIndexedPolyCurve", Points=point_list, SelfIntersect=False)
            bin_index = int(runs.bin_index[index])
            b = bins[bin_index]
            styled = self.style(curve, f"{path.layer} ATE {b.label}", b.color_rgb)
            (style,) = styled.Styles
            entities = (point_list, curve, style.CurveColour, style, styled)
            p, c, k, s, y = (int(e.id()) for e in entities)
            group.prototypes[bin_index] = Prototype((p, c, k, s, y))
            group.order[index] = int(curve.id())
            items.append(curve)
        text = np.ones(len(runs), dtype=bool)
        text[made] = False
        counts = np.diff(runs.offsets)
        group.bins = runs.bin_index[text]
        group.sizes = counts[text]
        # the text runs' file coordinates, mapped at once
        group.coordinates = self.coords(runs.vertices[np.repeat(text, counts)])
        legend = scale_words(placement.result)
        annotation = add_annotation(
            self,
            name=f"{path.name} ATE",
            kind=ATE_TYPE,
            description=legend,
            representation=("Curve3D", items),
            key=f"ate/{path.name}",
        )
        if len(group.bins):
            group.representation = int(annotation.Representation.Representations[0].id())
            self.run_groups.append(group)
        scale: dict[str, object] = {"Legend": legend}
        scale |= {f"Bin{k}": f"{b.label}: {hex_colour(b.color_rgb)}" for k, b in enumerate(bins, 1)}
        self.pset(annotation, "Loceval_ATE", scale)
        return annotation

    def _marker(self, marker: Marker, index: int) -> ifcopenshell.entity_instance:
        f = self.f
        ends = [marker.position] if marker.target is None else [marker.position, marker.target]
        xyz = self.coords(np.array(ends, dtype=np.float64)).tolist()
        items = [f.createIfcCartesianPoint(tuple(xyz[0]))]
        if marker.target is not None:
            line = [f.createIfcCartesianPoint(tuple(p)) for p in xyz]
            items.append(f.createIfcPolyline(line))
        rgb = next(p.color_rgb for p in self.placement.paths if p.name == marker.path)
        for item in items:
            self.style(item, f"{marker.path} markers", rgb)
        representation = f.create_entity(
            "IfcShapeRepresentation",
            ContextOfItems=self.annotation_ctx,
            RepresentationIdentifier="Annotation",
            RepresentationType="GeometricSet",
            Items=items,
        )
        return f.create_entity(
            "IfcAnnotation",
            GlobalId=self.guid(f"marker/{index}/{marker.path}"),
            Name=marker.label[:255],
            Description=marker.path,
            ObjectType=MARKER_TYPES[marker.kind],
            ObjectPlacement=self.local_placement(),
            Representation=f.createIfcProductDefinitionShape(None, None, [representation]),
        )

    def pset(
        self, target: ifcopenshell.entity_instance, name: str, values: dict[str, object]
    ) -> None:
        """Attach a property set ``name`` of ``values`` (None left out) to ``target``."""
        f = self.f
        properties = [
            f.create_entity("IfcPropertySingleValue", Name=key, NominalValue=self._value(value))
            for key, value in values.items()
            if value is not None
        ]
        pset = f.create_entity(
            "IfcPropertySet",
            GlobalId=self.guid(f"pset/{name}/{target.GlobalId}"),
            Name=name,
            HasProperties=properties,
        )
        f.create_entity(
            "IfcRelDefinesByProperties",
            GlobalId=self.guid(f"rel/{name}/{target.GlobalId}"),
            RelatedObjects=[target],
            RelatingPropertyDefinition=pset,
        )

    def _value(self, value: object) -> ifcopenshell.entity_instance:
        f = self.f
        if isinstance(value, bool):
            return f.createIfcBoolean(value)
        if isinstance(value, int):
            return f.createIfcInteger(value)
        if isinstance(value, float):
            return f.createIfcReal(value)
        text = value if isinstance(value, str) else json.dumps(value)
        return f.createIfcText(text)


def _evaluation_properties(placement: Placement) -> dict[str, object]:
    meta = placement.metadata()
    frame = meta["frame"]
    if not isinstance(frame, dict):  # pragma: no cover  (metadata() always nests it)
        msg = f"placement metadata has no frame dictionary: {frame!r}"
        raise TypeError(msg)
    return {
        "Generator": meta["generator"],
        "EvaluationId": placement.evaluation_id,
        "Title": placement.title,
        "CreatedAt": meta["created_at"],
        "Units": placement.units.value,
        "EvaluationFrame": frame["evaluation_frame"],
        "SiteMatrix_m": frame["site_matrix_m"],
        "SimplifyTolerance_m": placement.simplify_m,
        "MaxDeviation_m": placement.max_deviation_m,
    }


def _path_properties(path: PlacedPath, *, pieces: int) -> dict[str, object]:
    values: dict[str, object] = {
        "Kind": path.kind.value,
        "Source": path.source,
        "Layer": path.layer,
        "ColourHex": path.color_hex,
        "Poses": path.poses,
        "Vertices": len(path.vertices),
        "Pieces": pieces,
        "MaxDeviation_m": path.max_deviation_m,
    }
    if path.estimate is not None:
        values.update(_estimate_properties(path.estimate))
    return values


def _estimate_properties(est: EstimateResult) -> dict[str, object]:
    values: dict[str, object] = {}
    series: dict[str, tuple[ErrorSeries | None, str]] = {
        "ATE_translation": (est.ate_translation, "m"),
        "ATE_rotation": (est.ate_rotation, "deg"),
        "RPE_translation": (est.rpe_translation, "m"),
        "RPE_rotation": (est.rpe_rotation, "deg"),
    }
    for prefix, (errors, unit) in series.items():
        if errors is None or errors.stats.n == 0:
            continue
        stats = errors.stats
        for key in ("rmse", "mean", "median", "std", "min", "max"):
            values[f"{prefix}_{key}_{unit}"] = float(getattr(stats, key))
        values[f"{prefix}_n"] = int(stats.n)
    if est.verdict is not None:
        values["Verdict"] = est.verdict.result.upper()  # PASS, FAIL or UNDECIDED
        values["VerdictSummary"] = est.verdict.summary
        values["Tolerance_m"] = float(est.verdict.tolerance.distance_m)
        values["ShareWithin"] = float(est.verdict.share_within)
    return values
