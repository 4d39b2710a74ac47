"""The building's named spaces and placement checks, read for the core to place the stretches.

Reading the building needs the CAD libraries, so it lives here; the geometry of "which room
is this stretch in" lives in the core (:mod:`loceval.assessment.spaces`). The split: this
module turns the building file into plain polygons in the evaluation frame
(:class:`~loceval.assessment.spaces.Space`) plus the warnings about how the model is
placed, and :func:`placed_on_building` hands them to
:meth:`~loceval.evaluation.EvaluationResult.with_building`, which puts each stretch beyond
the tolerance in its space. Every output that shows the stretches (``result.json``, the report,
the viewer) reads the placed result, so they name the same rooms.

Where the spaces come from:

- **IFC**: every ``IfcSpace`` with a body, named ``Name`` and ``LongName`` joined
  (``"2.14 Office"``; either alone when the other is empty). Its footprint is the outline
  of its body's downward faces (the floor of an extruded room: any shape, L-shaped
  rooms too), its heights those of its body.
- **DXF floor plan**: rooms are *labelled closed outlines*. Every text (``TEXT``,
  ``MTEXT``) belongs to the smallest closed polyline around its insertion point; an outline
  that holds texts is a room named by them, read top to bottom and left to right
  (``"2.14"`` above ``"Office"`` gives ``"2.14 Office"``). Outlines without a text (walls,
  columns) and texts outside every outline are not rooms. A plan whose rooms are not
  closed polylines (walls drawn as loose lines) names no rooms: the stretches then carry
  no space rather than a guessed one.
- **OBJ, PLY, STL, GLB**: meshes name no spaces.

The placement check (:func:`~loceval.assessment.spaces.check_building_extent`) compares the
model's extents under the up axis used with the ground truth, and names the up axis that
would fit (mesh files) or says the paths lie outside the model.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from exporters.cad.building import (
    BuildingModel,
    FloorPlan,
    georeferenced_options,
    mesh_vertices_m,
    read_underlay,
    resolved_up,
)
from exporters.options import ExportOptions, FrontDoor, Units, UpAxis
from loceval.assessment.spaces import Building, Space, check_building_extent
from loceval.core.arrays import FloatArray
from loceval.core.display import display_text
from loceval.core.geometry import SimilarityTransform
from loceval.evaluation import EvaluationResult
from loceval.options import option

if TYPE_CHECKING:
    import ifcopenshell

__all__ = ["IFC_SPACES_RULE", "PLAN_ROOMS_RULE", "building_of", "placed_on_building"]

IFC_SPACES_RULE: Final = "IfcSpace Name and LongName, footprint of its body"
PLAN_ROOMS_RULE: Final = "texts inside closed polylines of the plan (the smallest around each)"
_KEY_DECIMALS: Final = 6  # vertices equal to a micrometre are one corner of a footprint


def placed_on_building(result: EvaluationResult, options: ExportOptions) -> EvaluationResult:
    """Return the evaluation with its building: each stretch in its space, the warnings.

    Unchanged without a building model, or when it was placed on this one already (every
    exporter calls this; the first does the work).

    Raises:
        ExportOptionsError: a building model that cannot be read.
    """
    if options.building is None:
        return result
    if result.building is not None and result.building.source == options.building.name:
        return result
    return result.with_building(building_of(result, options))


def building_of(result: EvaluationResult, options: ExportOptions) -> Building:
    """Return what the evaluation knows of its building: spaces and placement warnings.

    Args:
        result: the evaluation (its reference is the ground truth checked against the model).
        options: the building, its units and up axis, the site transform.

    Raises:
        ExportOptionsError: a building model that cannot be read.
    """
    if options.building is None:
        msg = "building_of needs options.building"
        raise ValueError(msg)
    placed = georeferenced_options(options)
    path = options.building
    underlay = read_underlay(path, units=placed.units, up=placed.building_up)
    to_frame = placed.site.inverse()
    if isinstance(underlay, FloorPlan):
        spaces = _plan_rooms(underlay, to_frame)
        rule = PLAN_ROOMS_RULE
        warnings: tuple[str, ...] = ()
    else:
        spaces = _ifc_spaces(path, to_frame) if path.suffix.lower() == ".ifc" else []
        rule = IFC_SPACES_RULE if path.suffix.lower() == ".ifc" else ""
        warnings = _extent_warnings(result, placed, underlay)
    return Building(
        source=path.name,
        spaces=tuple(spaces),
        spaces_from=rule if spaces else "",
        warnings=warnings,
    )


def _extent_warnings(
    result: EvaluationResult, options: ExportOptions, model: BuildingModel
) -> tuple[str, ...]:
    """Check the mesh's extents under its up axis (and the other one) against the paths."""
    path = options.building
    assert path is not None  # noqa: S101  (building_of checked it)
    truth = options.site.apply_positions(result.reference.positions_xyz)
    if path.suffix.lower() == ".ifc":  # IFC is Z up by definition: only the paths are checked
        bounds = {"z": _bounds(model.vertices_m)}
        chosen = "z"
    else:
        units = Units(options.units)
        chosen = resolved_up(path, options.building_up).value
        bounds = {
            up.value: _bounds(mesh_vertices_m(path, units=units, up=up))
            for up in (UpAxis.Z, UpAxis.Y)
        }
    return check_building_extent(
        bounds,
        chosen,
        truth,
        source=path.name,
        option=_up_option(FrontDoor(options.front_door)),
    )


def _up_option(front_door: FrontDoor) -> str:
    """Return how the user at ``front_door`` names the up-axis option."""
    spec = option("building_up")
    if front_door is FrontDoor.CLI:
        return spec.flag
    return f"{spec.words} (options.{spec.key})"


def _bounds(vertices: FloatArray) -> FloatArray:
    out: FloatArray = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
    return out


# --- DXF: labelled closed outlines -------------------------------------------------------


def _plan_rooms(plan: FloorPlan, to_frame: SimilarityTransform) -> list[Space]:
    """Return the plan's labelled closed outlines as spaces, in the evaluation frame."""
    if not plan.outlines or not plan.labels:
        return []
    outlines = [o for o in plan.outlines if _ring_area(o) > 0.0]
    areas = np.array([_ring_area(o) for o in outlines])
    held: dict[int, list[tuple[str, tuple[float, float]]]] = {}
    for text, at in plan.labels:  # one iteration per text of the plan
        point = np.array([at])
        around = [k for k, o in enumerate(outlines) if _inside_ring(point, o)[0]]
        if around:  # the smallest outline around the text
            held.setdefault(min(around, key=lambda k: areas[k]), []).append((text, at))
    spaces = []
    for k, texts in held.items():
        # read top to bottom, left to right (rows of about a text's height)
        texts.sort(key=lambda t: (-round(t[1][1], 1), t[1][0]))
        name = display_text(" ".join(t for t, _ in texts))
        ring = outlines[k]
        xyz = np.column_stack([ring, np.zeros(len(ring))])
        spaces.append(Space(name, to_frame.apply_positions(xyz)[:, :2]))
    return spaces


def _ring_area(ring: FloatArray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _inside_ring(points: FloatArray, ring: FloatArray) -> np.ndarray:
    """Crossing-number test of (M, 2) points against a ring (a handful of points here)."""
    from loceval.assessment.spaces import locate_in_spaces  # noqa: PLC0415

    xyz = np.column_stack([points, np.zeros(len(points))])
    inside: np.ndarray = locate_in_spaces(xyz, [Space("ring", ring)]) == 0
    return inside


# --- IFC: IfcSpace bodies ------------------------------------------------------------------


def _ifc_spaces(path: Path, to_frame: SimilarityTransform) -> list[Space]:
    """Return the IFC's spaces in the evaluation frame (model coordinates mapped back)."""
    import ifcopenshell  # noqa: PLC0415
    import ifcopenshell.geom  # noqa: PLC0415

    from exporters.cad.building import _map_conversion, _open_ifc  # noqa: PLC0415

    model = _open_ifc(path)
    found = _map_conversion(model)
    # the IFC's own coordinates -> model coordinates: its map conversion, as for its body
    to_model = found[0] if found is not None else SimilarityTransform.identity()
    settings = ifcopenshell.geom.settings()  # type: ignore[no-untyped-call]
    settings.set("use-world-coords", True)  # noqa: FBT003  (ifcopenshell's API)
    spaces = []
    for entity in model.by_type("IfcSpace"):  # one iteration per space of the building
        if entity.Representation is None:
            continue
        try:
            shape: Any = ifcopenshell.geom.create_shape(settings, entity)
        except (RuntimeError, ValueError, ifcopenshell.Error):
            continue  # a space whose body cannot be built names no place
        geometry = shape.geometry
        vertices = np.asarray(geometry.verts, dtype=np.float64).reshape(-1, 3)
        faces = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
        if not len(faces):
            continue
        placed = to_frame.apply_positions(to_model.apply_positions(vertices))
        ring = _footprint(placed, faces)
        if ring is None:
            continue
        spaces.append(
            Space(
                _space_name(entity),
                ring,
                floor_m=float(placed[:, 2].min()),
                ceiling_m=float(placed[:, 2].max()),
            )
        )
    return spaces


def _space_name(entity: ifcopenshell.entity_instance) -> str:
    parts = [str(p).strip() for p in (entity.Name, entity.LongName) if p]
    name = display_text(" ".join(p for p in parts if p))
    return name or f"IfcSpace #{entity.id()}"


def _footprint(vertices: FloatArray, faces: np.ndarray) -> FloatArray | None:
    """Return the outline (K, 2) of a body's downward faces at its floor, or None.

    The floor of an extruded room is a set of triangles facing down; the edges that only
    one of them uses are its outline, chained into rings; the largest ring is the room.
    """
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    floor_z = float(vertices[:, 2].min())
    centroid_z = (a[:, 2] + b[:, 2] + c[:, 2]) / 3.0
    down = (lengths > 0) & (normals[:, 2] < -0.5 * lengths) & (centroid_z < floor_z + 0.05)
    if not down.any():
        return None
    keys = np.round(vertices[:, :2], _KEY_DECIMALS)
    _, corner = np.unique(keys, axis=0, return_inverse=True)
    corner = corner.ravel()
    tri = corner[faces[down]]
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    undirected = np.sort(edges, axis=1)
    unique, counts = np.unique(undirected, axis=0, return_counts=True)
    boundary = unique[counts == 1]
    rings = _chain(boundary)
    if not rings:
        return None
    points = np.zeros((int(corner.max()) + 1, 2))
    points[corner] = vertices[:, :2]
    best = max((points[r] for r in rings), key=_ring_area)
    return best if _ring_area(best) > 0.0 and len(best) >= 3 else None


def _chain(edges: np.ndarray) -> list[list[int]]:
    """Chain undirected boundary edges into closed rings of corner indices."""
    neighbours: dict[int, list[int]] = {}
    for p, q in edges.tolist():  # one iteration per outline edge of one space
        neighbours.setdefault(p, []).append(q)
        neighbours.setdefault(q, []).append(p)
    rings = []
    seen: set[tuple[int, int]] = set()
    for start in list(neighbours):
        for first in neighbours[start]:
            if (start, first) in seen:
                continue
            ring, prev, here = [start], start, first
            seen.add((start, first))
            while here != start and len(ring) <= len(edges):
                ring.append(here)
                nxt = next((n for n in neighbours[here] if n != prev), None)
                if nxt is None:
                    break
                seen.add((here, nxt))
                prev, here = here, nxt
            if here == start and len(ring) >= 3:
                rings.append(ring)
                seen.update(zip(ring[1:] + ring[:1], ring, strict=True))
    return rings
