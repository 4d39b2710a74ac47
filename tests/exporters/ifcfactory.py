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


# --- a two-room office: the same walls as IFC, DXF plan and GLB (tests/exporters/office.py) ---

OFFICE_WALL_M = 0.2
"""Outer wall thickness of the office, metres (the partition is half as thick)."""
OFFICE_HEIGHT_M = 3.0
OFFICE_WALLS: list[tuple[float, float, float, float, float]] = [
    # (start x, start y, length, angle, thickness): along local +x, thickness to local +y
    (-0.2, -0.2, 10.4, 0.0, 0.2),  # south: y -0.2 .. 0
    (10.2, -0.2, 6.4, math.pi / 2, 0.2),  # east: x 10 .. 10.2
    (10.2, 6.2, 10.4, math.pi, 0.2),  # north: y 6 .. 6.2
    (-0.2, 6.2, 6.4, -math.pi / 2, 0.2),  # west: x -0.2 .. 0
    (5.05, 0.0, 2.5, math.pi / 2, 0.1),  # partition south of its door: x 4.95 .. 5.05
    (5.05, 3.5, 2.5, math.pi / 2, 0.1),  # partition north of its door (door: y 2.5 .. 3.5)
]
"""The office's walls: inside x 0..10 m, y 0..6 m, a partition at x = 5 m with a door."""
OFFICE_ROOMS: dict[tuple[str, str], tuple[float, float, float, float]] = {
    ("2.13", "Meeting"): (0.0, 4.95, 0.0, 6.0),
    ("2.14", "Office"): (5.05, 10.0, 0.0, 6.0),
}
"""(Name, LongName) -> (x min, x max, y min, y max) of each room, metres."""


def wall_corners(x: float, y: float, length: float, angle: float, thickness: float) -> np.ndarray:
    """Return the (4, 2) footprint corners of one of :data:`OFFICE_WALLS`, counter-clockwise."""
    along = np.array([math.cos(angle), math.sin(angle)])
    across = np.array([-math.sin(angle), math.cos(angle)])
    p0 = np.array([x, y])
    return np.array([p0, p0 + length * along, p0 + length * along + thickness * across,
                     p0 + thickness * across])  # fmt: skip


def write_office(path: Path) -> Path:
    """Write a millimetre IFC4 of the two-room office: walls and two named IfcSpaces."""
    f = ifcopenshell.api.project.create_file(version="IFC4")
    project = ifcopenshell.api.root.create_entity(f, ifc_class="IfcProject", name="Office")
    ifcopenshell.api.unit.assign_unit(f)
    model = ifcopenshell.api.context.add_context(f, context_type="Model")
    body = ifcopenshell.api.context.add_context(
        f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=model
    )
    site = ifcopenshell.api.root.create_entity(f, ifc_class="IfcSite", name="Site")
    building = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuilding", name="B")
    storey = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuildingStorey", name="OG2")
    ifcopenshell.api.aggregate.assign_object(f, relating_object=project, products=[site])
    ifcopenshell.api.aggregate.assign_object(f, relating_object=site, products=[building])
    ifcopenshell.api.aggregate.assign_object(f, relating_object=building, products=[storey])
    walls = []
    for k, (x, y, length, angle, thickness) in enumerate(OFFICE_WALLS):
        wall = ifcopenshell.api.root.create_entity(f, ifc_class="IfcWall", name=f"Wall {k}")
        rep = ifcopenshell.api.geometry.add_wall_representation(
            f, context=body, length=length, height=OFFICE_HEIGHT_M, thickness=thickness
        )
        ifcopenshell.api.geometry.assign_representation(f, product=wall, representation=rep)
        ifcopenshell.api.geometry.edit_object_placement(f, product=wall, matrix=_pose(x, y, angle))
        walls.append(wall)
    ifcopenshell.api.spatial.assign_container(f, products=walls, relating_structure=storey)
    spaces = []
    for (name, long_name), (x0, x1, y0, y1) in OFFICE_ROOMS.items():
        space = ifcopenshell.api.root.create_entity(f, ifc_class="IfcSpace", name=name)
        space.LongName = long_name
        rep = ifcopenshell.api.geometry.add_slab_representation(
            f, context=body, depth=OFFICE_HEIGHT_M,
            polyline=[(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)],
        )  # fmt: skip
        ifcopenshell.api.geometry.assign_representation(f, product=space, representation=rep)
        ifcopenshell.api.geometry.edit_object_placement(f, product=space, matrix=np.eye(4))
        spaces.append(space)
    ifcopenshell.api.aggregate.assign_object(f, relating_object=storey, products=spaces)
    f.write(str(path))
    return path
