"""Build small IFC4 building models with ifcopenshell's API, for the building-model tests."""

from __future__ import annotations

import math
from pathlib import Path

import ifcopenshell
import ifcopenshell.api.aggregate
import ifcopenshell.api.context
import ifcopenshell.api.geometry
import ifcopenshell.api.georeference
import ifcopenshell.api.project
import ifcopenshell.api.root
import ifcopenshell.api.spatial
import ifcopenshell.api.unit
import numpy as np

ROOM_X_M = 6.0
"""Inner length of the room along x, metres (walls 0.2 m thick, 3 m high, outside it)."""
ROOM_Y_M = 4.0
"""Inner width of the room along y, metres."""
DOOR_X_M = (2.5, 3.5)
"""The door in the south wall (y = 0 .. -0.2) spans these x, metres."""
WALL_M = 0.2
GRID_YAW_DEG = 30.0
"""How far ``GRID_CONVERSION`` turns the room, degrees."""
GRID_CONVERSION: dict[str, float] = {
    "Eastings": 512340.0,
    "Northings": 5403210.5,
    "OrthogonalHeight": 112.3,
    "XAxisAbscissa": math.cos(math.radians(GRID_YAW_DEG)),
    "XAxisOrdinate": math.sin(math.radians(GRID_YAW_DEG)),
    "Scale": 0.001,  # the IFC is in millimetres, the map in metres
}
"""A ``map_conversion`` for :func:`write_room`: the room on a national grid, turned 30 degrees."""


def write_room(
    path: Path,
    *,
    map_conversion: dict[str, float] | None = None,
    crs: str = "EPSG:25832",
) -> Path:
    """Write a millimetre IFC of one room: four walls (the south one in two pieces) and a door.

    The room's inside spans x 0..6 m, y 0..4 m in the IFC's own coordinates; the walls
    stand outside it, 0.2 m thick, from z 0 to 3 m; the door leaf (0.05 m thick, 2.1 m
    high) fills the gap x 2.5..3.5 m of the south wall.
    """
    f = ifcopenshell.api.project.create_file(version="IFC4")
    project = ifcopenshell.api.root.create_entity(f, ifc_class="IfcProject", name="Lab")
    ifcopenshell.api.unit.assign_unit(f)  # millimetres, as Revit and ArchiCAD export
    model = ifcopenshell.api.context.add_context(f, context_type="Model")
    body = ifcopenshell.api.context.add_context(
        f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=model
    )
    site = ifcopenshell.api.root.create_entity(f, ifc_class="IfcSite", name="Site")
    storey = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuildingStorey", name="EG")
    ifcopenshell.api.aggregate.assign_object(f, relating_object=project, products=[site])
    ifcopenshell.api.aggregate.assign_object(f, relating_object=site, products=[storey])
    # (start x, start y, length, angle): walls run along their local +x, thickness to +y
    w = WALL_M
    walls = [
        (-w, -w, DOOR_X_M[0] + w, 0.0),  # south, west of the door
        (DOOR_X_M[1], -w, ROOM_X_M - DOOR_X_M[1] + w, 0.0),  # south, east of the door
        (ROOM_X_M + w, -w, ROOM_Y_M + 2 * w, math.pi / 2),  # east
        (ROOM_X_M + w, ROOM_Y_M + w, ROOM_X_M + 2 * w, math.pi),  # north
        (-w, ROOM_Y_M + w, ROOM_Y_M + 2 * w, -math.pi / 2),  # west
    ]
    elements = []
    for k, (x, y, length, angle) in enumerate(walls):
        wall = ifcopenshell.api.root.create_entity(f, ifc_class="IfcWall", name=f"Wall {k}")
        rep = ifcopenshell.api.geometry.add_wall_representation(
            f, context=body, length=length, height=3.0, thickness=w
        )
        ifcopenshell.api.geometry.assign_representation(f, product=wall, representation=rep)
        ifcopenshell.api.geometry.edit_object_placement(f, product=wall, matrix=_pose(x, y, angle))
        elements.append(wall)
    door = ifcopenshell.api.root.create_entity(f, ifc_class="IfcDoor", name="Door")
    leaf = ifcopenshell.api.geometry.add_wall_representation(
        f, context=body, length=DOOR_X_M[1] - DOOR_X_M[0], height=2.1, thickness=0.05
    )
    ifcopenshell.api.geometry.assign_representation(f, product=door, representation=leaf)
    ifcopenshell.api.geometry.edit_object_placement(
        f, product=door, matrix=_pose(DOOR_X_M[0], -0.125, 0.0)
    )
    elements.append(door)
    ifcopenshell.api.spatial.assign_container(f, products=elements, relating_structure=storey)
    if map_conversion is not None:
        ifcopenshell.api.georeference.add_georeferencing(f, name=crs)
        ifcopenshell.api.georeference.edit_georeferencing(
            f, coordinate_operation=map_conversion, projected_crs={"Name": crs}
        )
    f.write(str(path))
    return path


def _pose(x_m: float, y_m: float, angle_rad: float) -> np.ndarray:
    m = np.eye(4)
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = [x_m, y_m]
    return m
