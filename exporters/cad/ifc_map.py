"""The IFC's map and excursion annotations (``paths.ifc``), as the DXF's layers show them.

With a measured map (:mod:`loceval.maps`) the IFC gains, in the same site and units as
the paths:

- ``map plan`` (``ObjectType``): the plan's walls the map was measured against, one
  ``IfcIndexedPolyCurve`` per wall segment (grey), all on one shared point list; its
  property set ``Loceval_Map`` holds the map's figures: wall distances as placed, after
  the best rigid and similarity fits, each fit's scale, rotation and translation, the
  plan coverage and the clutter count (the result document's ``map``);
- ``map walls``: the wall cells as one ``PointCloud`` (an ``IfcCartesianPointList3D``)
  per distance bin, each coloured like the report's bins and named by its bin, plus one
  of clutter (magenta): the same capped cells as the DXF and 3DM
  (:func:`exporters.cad.dxf_map.placed_cells`).

With excursions (:mod:`exporters.cad.excursions`): one ``excursion`` annotation per
stretch outside the tracked room, the estimate's path as a purple curve, named by its label,
with the figures in ``Loceval_Excursion``.

Everything sits at the reference's median height, where the plan was cut.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final, Protocol

import ifcopenshell
import numpy as np

from exporters.cad.dxf_map import placed_cells
from exporters.cad.excursions import EXCURSION_RGB, placed_excursions
from exporters.cad.placement import Placement
from exporters.colours import map_bins
from loceval.core.arrays import FloatArray

__all__ = [
    "EXCURSION_TYPE",
    "MAP_TYPES",
    "IfcBuilder",
    "add_annotation",
    "add_excursions",
    "add_map",
]

MAP_TYPES: Final = {"plan": "map plan", "walls": "map walls"}
"""``ObjectType`` of the map's annotations."""
EXCURSION_TYPE: Final = "excursion"
"""``ObjectType`` of a stretch outside the tracked room."""
_PLAN_RGB: Final = (158, 158, 158)


class IfcBuilder(Protocol):
    """What these annotations need of :class:`exporters.cad.ifc.IfcBuilder`."""

    f: ifcopenshell.file
    placement: Placement
    annotation_ctx: ifcopenshell.entity_instance

    def point_list(self, points: FloatArray) -> ifcopenshell.entity_instance:
        """An ``IfcCartesianPointList3D`` of (M, 3) file coordinates."""

    def coords(self, model: FloatArray) -> FloatArray:
        """Model coordinates -> the file's coordinates."""

    def guid(self, key: str) -> str:
        """A GlobalId stable for the evaluation and ``key``."""

    def local_placement(self) -> ifcopenshell.entity_instance:
        """A placement at the site's origin."""

    def style(
        self, item: ifcopenshell.entity_instance, name: str, rgb: Sequence[int]
    ) -> ifcopenshell.entity_instance:
        """Colour a representation item; return its ``IfcStyledItem``."""

    def pset(
        self, target: ifcopenshell.entity_instance, name: str, values: dict[str, object]
    ) -> None:
        """Attach a property set."""


_CLUTTER_RGB: Final = (194, 24, 91)


def add_map(builder: IfcBuilder) -> list[ifcopenshell.entity_instance]:
    """Return the map's annotations (none without a measured map)."""
    placement = builder.placement
    found = placement.result.map
    cells = placed_cells(placement)
    if found is None or cells is None:
        return []
    xyz, distance, clutter = cells
    z = float(np.median(placement.result.reference.positions_xyz[:, 2]))
    ends = found.plan_xy.reshape(-1, 2)
    plan = placement.to_model(np.column_stack([ends, np.full(len(ends), z)]))
    out = [_plan(builder, builder.coords(plan), found.to_dict())]
    bins = map_bins(found.distance_m, placement.result.config.thresholds_m)
    index = np.searchsorted([b.high_m for b in bins[:-1]], distance, side="left")
    index[clutter] = len(bins)
    names = [*(f"map walls {b.label}" for b in bins), "map clutter"]
    colours = [*(b.color_rgb for b in bins), _CLUTTER_RGB]
    points = builder.coords(xyz)
    for k, (name, rgb) in enumerate(zip(names, colours, strict=True)):  # one cloud per bin
        chosen = points[index == k]
        if len(chosen):
            out.append(_cloud(builder, name, rgb, chosen))
    return out


def _plan(
    builder: IfcBuilder, ends: np.ndarray, figures: dict[str, object]
) -> ifcopenshell.entity_instance:
    """The plan's walls: one curve per segment over one point list, and the map's figures."""
    f = builder.f
    shared = builder.point_list(ends)
    items = [  # one curve per wall segment (1-based indices into the shared list)
        f.create_entity(
            "IfcIndexedPolyCurve",
            Points=shared,
            Segments=[f.create_entity("IfcLineIndex", (2 * k + 1, 2 * k + 2))],
            SelfIntersect=False,
        )
        for k in range(len(ends) // 2)
    ]
    for item in items:
        builder.style(item, MAP_TYPES["plan"], _PLAN_RGB)
    annotation = add_annotation(
        builder,
        name="map plan",
        kind=MAP_TYPES["plan"],
        description=f"loceval: the building plan the map {figures['source']} was measured against",
        representation=("Curve3D", items),
    )
    builder.pset(annotation, "Loceval_Map", _map_properties(figures))
    return annotation


def _cloud(
    builder: IfcBuilder, name: str, rgb: tuple[int, int, int], points: np.ndarray
) -> ifcopenshell.entity_instance:
    cloud = builder.point_list(points)
    builder.style(cloud, name, rgb)
    annotation = add_annotation(
        builder,
        name=name,
        kind=MAP_TYPES["walls"],
        description="loceval: map wall cells by distance to the plan",
        representation=("PointCloud", [cloud]),
    )
    builder.pset(annotation, "Loceval_MapCells", {"Cells": len(points), "Bin": name})
    return annotation


def add_excursions(builder: IfcBuilder) -> list[ifcopenshell.entity_instance]:
    """Return one annotation per excursion: the path outside the room, named by its label."""
    out = []
    for k, (path, model) in enumerate(placed_excursions(builder.placement)):  # a few stretches
        f = builder.f
        curve = f.create_entity(
            "IfcIndexedPolyCurve",
            Points=builder.point_list(builder.coords(model)),
            SelfIntersect=False,
        )
        builder.style(curve, EXCURSION_TYPE, EXCURSION_RGB)
        annotation = add_annotation(
            builder,
            name=path.label[:255],
            kind=EXCURSION_TYPE,
            description=f"{path.estimate}: estimate path while the reference was lost",
            representation=("Curve3D", [curve]),
            key=f"excursion/{k}/{path.estimate}",
        )
        x = path.excursion
        builder.pset(
            annotation,
            "Loceval_Excursion",
            {
                "Estimate": path.estimate,
                "Duration_s": path.duration_s,
                "PathLength_m": x.path_length_m,
                "ErrorBefore_m": x.error_before_m,
                "ErrorAfter_m": x.error_after_m,
                "DriftPerMetre": x.drift_per_m,
            },
        )
        out.append(annotation)
    return out


def add_annotation(
    builder: IfcBuilder,
    *,
    name: str,
    kind: str,
    description: str,
    representation: tuple[str, list[ifcopenshell.entity_instance]],
    key: str | None = None,
) -> ifcopenshell.entity_instance:
    """Return an ``IfcAnnotation`` of ``representation`` (type, items) at the site's origin."""
    f = builder.f
    shape = f.create_entity(
        "IfcShapeRepresentation",
        ContextOfItems=builder.annotation_ctx,
        RepresentationIdentifier="Annotation",
        RepresentationType=representation[0],
        Items=representation[1],
    )
    return f.create_entity(
        "IfcAnnotation",
        GlobalId=builder.guid(key or f"map/{name}"),
        Name=name,
        Description=description,
        ObjectType=kind,
        ObjectPlacement=builder.local_placement(),
        Representation=f.createIfcProductDefinitionShape(None, None, [shape]),
    )


def _map_properties(figures: dict[str, object]) -> dict[str, object]:
    """The result document's ``map`` as flat properties (numbers as numbers, rest as JSON)."""
    values: dict[str, object] = {}
    distance = figures["wall_distance_m"]
    if isinstance(distance, dict):
        values.update({f"WallDistance_{k}": v for k, v in distance.items()})
    for key in ("source", "resolution_m", "wall_cells", "plan_coverage", "clutter_cells"):
        values[key] = figures[key]
    values["clutter_m"] = figures["clutter_m"]
    values["scale_error_pct"] = figures["scale_error_pct"]
    values["drift"] = figures["drift"]
    values["within"] = figures["within"]
    axis_scales = figures["axis_scales"]
    if isinstance(axis_scales, dict):
        values.update({f"axis_{k}": v for k, v in axis_scales.items() if v is not None})
    fit = figures["fit"]
    if isinstance(fit, dict):
        for name, found in fit.items():
            if not isinstance(found, dict):
                continue
            values[f"{name}_scale"] = found["scale"]
            values[f"{name}_rotation_deg"] = found["rotation_deg"]
            values[f"{name}_translation_m"] = found["translation_m"]
            rmse = found["wall_distance_m"]
            if isinstance(rmse, dict):
                values[f"{name}_rmse_m"] = rmse["rmse"]
    return values
