"""Building models in: the one place that reads building files (mesh, IFC, DXF floor plan).

A building model is a triangle mesh in *model coordinates* (metres, Z up: the coordinates
the site transform maps the evaluation frame into). :func:`read_building` reads

- OBJ, PLY, STL (trimesh): model coordinates in the given units, Z up as CAD programs
  export them, or Y up (``up="y"``) as many OBJ exporters write them;
- GLB (trimesh): metres, Y up as the glTF specification says, or Z up (``up="z"``) for a
  file written from Z-up data without turning it (as trimesh and many exporters write it);
- IFC (ifcopenshell.geom): every element with a body, openings cut. When the file has an
  ``IfcMapConversion`` its model coordinates are the map's (Eastings, Northings, height
  in metres) and the conversion is the site transform: the evaluation frame is taken to be
  the IFC's own engineering frame, so the paths land where the building's own
  georeference puts them. :func:`read_georeference` reads only that, without geometry.

A 2D DXF drawing (``LINE``, ``LWPOLYLINE``, ``POLYLINE``, ``ARC``/``CIRCLE`` approximated)
is read by :func:`read_floor_plan` as a :class:`FloorPlan` for the plan-view underlay.

:func:`section_segments` cuts either at a height and returns the floor plan as line
segments in the evaluation frame: what the report's plan views draw under the paths.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from exporters.errors import ExportOptionsError
from exporters.options import ExportOptions, Units, UpAxis
from loceval.core.arrays import FloatArray
from loceval.core.geometry import SimilarityTransform

if TYPE_CHECKING:
    import ifcopenshell
    from ezdxf.entities.circle import Circle
    from ezdxf.entities.lwpolyline import LWPolyline
    from ezdxf.entities.mtext import MText
    from ezdxf.entities.polyline import Polyline
    from ezdxf.entities.text import Text

__all__ = [
    "FRAME_BUILDING_UP_TO",
    "MESH_SUFFIXES",
    "BuildingModel",
    "FloorPlan",
    "georeferenced_options",
    "mesh_vertices_m",
    "read_building",
    "read_floor_plan",
    "read_georeference",
    "read_underlay",
    "resolved_up",
    "section_segments",
]

MESH_SUFFIXES: Final = (".obj", ".ply", ".stl", ".glb", ".ifc")
"""Building files :func:`read_building` reads as a mesh."""
FRAME_BUILDING_UP_TO: Final = 20.0
"""A building model up to this many times the paths' size is framed with them: the report's
plan views and the viewer's first view show its outer walls; a campus is not framed."""
_Y_UP_TO_Z_UP: Final = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""(3, 3) rotation +90° about X: (x, y, z) Y-up -> (x, -z, y) Z-up."""
_INSUNITS_PER_METRE: Final = {
    1: 39.37007874015748,
    2: 3.280839895013123,
    4: 1000.0,
    5: 100.0,
    6: 1.0,
}
_SI_PREFIX: Final = {
    "KILO": 1e3,
    "HECTO": 1e2,
    "DECA": 1e1,
    "DECI": 1e-1,
    "CENTI": 1e-2,
    "MILLI": 1e-3,
}
_ARC_SEGMENT_RAD: Final = math.radians(5.0)


@dataclass(frozen=True, slots=True, eq=False)
class BuildingModel:
    """A building as a triangle mesh in model coordinates.

    Attributes:
        vertices_m: (V, 3) float64 model coordinates, metres, Z up.
        faces: (F, 3) int64 vertex indices of the triangles.
        source: the file it was read from.
        site: evaluation frame (metres) -> model coordinates (metres) the file itself
            gives (an IFC's map conversion), or None.
        crs: the projected CRS the model coordinates are in (``"EPSG:25832"``), or None.
    """

    vertices_m: FloatArray
    faces: NDArray[np.int64]
    source: Path
    site: SimilarityTransform | None = None
    crs: str | None = None

    def __post_init__(self) -> None:
        """Copy the arrays read-only and check their shapes."""
        vertices = np.array(self.vertices_m, dtype=np.float64)
        faces = np.array(self.faces, dtype=np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
            msg = (
                f"A building model needs (V, 3) vertices and (F, 3) faces, got "
                f"{vertices.shape!r} and {faces.shape!r}; this is a bug, please report it."
            )
            raise ValueError(msg)
        vertices.flags.writeable = False
        faces.flags.writeable = False
        object.__setattr__(self, "vertices_m", vertices)
        object.__setattr__(self, "faces", faces)


@dataclass(frozen=True, slots=True, eq=False)
class FloorPlan:
    """A 2D drawing of the building as line segments in model coordinates.

    Attributes:
        segments_m: (K, 2, 2) float64 segment end points (x, y), model metres.
        source: the file it was read from.
        outlines: the closed polylines' rings, (K, 2) model metres each (the candidates
            for rooms, :mod:`exporters.cad.spaces`).
        labels: the texts (``TEXT``, ``MTEXT``) and their insertion points (x, y),
            model metres.
    """

    segments_m: FloatArray
    source: Path
    outlines: tuple[FloatArray, ...] = ()
    labels: tuple[tuple[str, tuple[float, float]], ...] = ()

    def __post_init__(self) -> None:
        """Copy the array read-only."""
        segments = np.array(self.segments_m, dtype=np.float64).reshape(-1, 2, 2)
        segments.flags.writeable = False
        object.__setattr__(self, "segments_m", segments)


# --- reading -------------------------------------------------------------------------------


def resolved_up(path: Path, up: UpAxis = UpAxis.FORMAT) -> UpAxis:
    """Return the up axis a mesh file is read with: ``up``, or its format's convention.

    ``format`` means Y for a GLB (the glTF specification is Y up) and Z for OBJ, PLY and
    STL (as CAD programs export them); an IFC is always Z up and a DXF plan has none.
    """
    up = UpAxis(up)
    if up is not UpAxis.FORMAT:
        return up
    return UpAxis.Y if path.suffix.lower() == ".glb" else UpAxis.Z


def read_building(
    path: Path, *, units: Units = Units.M, up: UpAxis = UpAxis.FORMAT
) -> BuildingModel:
    """Read a building model (OBJ, PLY, STL, GLB or IFC) as a mesh in model coordinates.

    Read once per file, units and up axis (while the file is unchanged): the viewer, the
    report's plan views, the GLB and the building checks share one reading.

    Args:
        path: the file.
        units: the length units of an OBJ, PLY or STL file (GLB is metres; IFC says).
        up: the up axis of a mesh file (:func:`resolved_up`; an IFC is always Z up).

    Returns:
        The building; for an IFC with a map conversion, with its site and CRS.

    Raises:
        ExportOptionsError: a missing, unsupported or unreadable file, or one without
            triangles.
    """
    suffix = _check_file(path, MESH_SUFFIXES)
    axis = UpAxis.Z if suffix == ".ifc" else resolved_up(path, up)
    return _read_building_cached(path, _file_key(path), Units(units), axis)


@functools.lru_cache(maxsize=8)
def _read_building_cached(
    path: Path, _key: tuple[int, int], units: Units, up: UpAxis
) -> BuildingModel:
    """Read a building; cached by path, size and modification time (``_key``)."""
    suffix = path.suffix.lower()
    if suffix == ".ifc":
        return _read_ifc(path)
    return BuildingModel(mesh_vertices_m(path, units=units, up=up), _raw_mesh(path)[1], path)


def mesh_vertices_m(path: Path, *, units: Units, up: UpAxis) -> FloatArray:
    """Return a mesh file's (V, 3) vertices in model metres, Z up, read with ``up``.

    Args:
        path: an OBJ, PLY, STL or GLB file.
        units: the length units of an OBJ, PLY or STL file (a GLB is metres).
        up: its up axis (``format``: :func:`resolved_up`).
    """
    vertices = _raw_mesh(path)[0]
    if path.suffix.lower() != ".glb":
        vertices = vertices / Units(units).per_metre
    if resolved_up(path, up) is UpAxis.Y:
        vertices = vertices @ _Y_UP_TO_Z_UP.T
    return vertices


def _file_key(path: Path) -> tuple[int, int]:
    """Return (size, modification time in ns): a changed file is read again."""
    try:
        stat = path.stat()
    except OSError as err:
        msg = f"The building model {str(path)!r} cannot be read ({err.strerror}); check the path."
        raise ExportOptionsError(msg, option="building") from err
    return stat.st_size, stat.st_mtime_ns


def _raw_mesh(path: Path) -> tuple[FloatArray, NDArray[np.int64]]:
    """Return a mesh file's vertices as stored and its faces (read once per file version)."""
    return _raw_mesh_cached(path, _file_key(path))


@functools.lru_cache(maxsize=4)
def _raw_mesh_cached(path: Path, _key: tuple[int, int]) -> tuple[FloatArray, NDArray[np.int64]]:
    vertices, faces = _read_trimesh(path, path.suffix.lower())
    vertices.flags.writeable = False
    faces.flags.writeable = False
    return vertices, faces


def read_floor_plan(path: Path, *, units: Units = Units.M) -> FloorPlan:
    """Read the 2D lines of a DXF drawing's model space as a floor plan.

    Lines, polylines (light-weight and 2D/3D, closed or open), arcs and circles (in 5°
    chords) become segments; their Z is dropped. Closed polylines are also kept as
    outlines and texts as labels (the plan's rooms, :mod:`exporters.cad.spaces`). The
    drawing's ``$INSUNITS`` gives its units; ``units`` is used when the drawing leaves
    them unset. Read once per file version and units.

    Args:
        path: the DXF file.
        units: the drawing's units when ``$INSUNITS`` is unset.

    Raises:
        ExportOptionsError: a missing or unreadable file, or one without lines.
    """
    _check_file(path, (".dxf",))
    return _read_floor_plan_cached(path, _file_key(path), Units(units))


@functools.lru_cache(maxsize=4)
def _read_floor_plan_cached(path: Path, _key: tuple[int, int], units: Units) -> FloorPlan:
    return _read_floor_plan(path, units=units)


def _read_floor_plan(path: Path, *, units: Units = Units.M) -> FloorPlan:
    """Read a DXF floor plan (:func:`read_floor_plan`), uncached."""
    from ezdxf.entities.arc import Arc  # noqa: PLC0415
    from ezdxf.entities.circle import Circle  # noqa: PLC0415
    from ezdxf.entities.line import Line  # noqa: PLC0415
    from ezdxf.entities.lwpolyline import LWPolyline  # noqa: PLC0415
    from ezdxf.entities.mtext import MText  # noqa: PLC0415
    from ezdxf.entities.polyline import Polyline  # noqa: PLC0415
    from ezdxf.entities.text import Text  # noqa: PLC0415
    from ezdxf.filemanagement import readfile  # noqa: PLC0415  (only a floor plan needs it)
    from ezdxf.lldxf.const import DXFError  # noqa: PLC0415

    try:
        doc = readfile(str(path))
    except (OSError, DXFError, UnicodeDecodeError) as err:
        msg = f"The floor plan {str(path)!r} cannot be read as DXF ({err}); check the file."
        raise ExportOptionsError(msg, option="building") from err
    per_metre = _INSUNITS_PER_METRE.get(int(doc.header.get("$INSUNITS", 0)), units.per_metre)
    chains: list[FloatArray] = []
    outlines: list[FloatArray] = []
    labels: list[tuple[str, tuple[float, float]]] = []
    for entity in doc.modelspace():  # one iteration per drawing entity, not per vertex
        if isinstance(entity, Line):
            chains.append(np.array([entity.dxf.start.xyz, entity.dxf.end.xyz])[:, :2])
        elif isinstance(entity, LWPolyline | Polyline):
            xy, closed = _polyline(entity)
            chains.append(np.vstack([xy, xy[:1]]) if closed else xy)
            if closed and len(xy) >= 3:
                outlines.append(xy / per_metre)
        elif isinstance(entity, Text | MText):
            labels += _label(entity, per_metre)
        elif isinstance(entity, Arc):  # an ARC is a CIRCLE with angles: test it first
            chains.append(_arc(entity, full=False))
        elif isinstance(entity, Circle):
            chains.append(_arc(entity, full=True))
    segments = [np.stack([c[:-1], c[1:]], axis=1) for c in chains if len(c) >= 2]
    if not segments:
        msg = (
            f"The floor plan {str(path)!r} has no lines in its model space; export the "
            "plan with its walls as lines or polylines."
        )
        raise ExportOptionsError(msg, option="building")
    return FloorPlan(
        np.concatenate(segments) / per_metre, path, outlines=tuple(outlines), labels=tuple(labels)
    )


def _label(entity: Text | MText, per_metre: float) -> list[tuple[str, tuple[float, float]]]:
    """Return a text's words and insertion point (x, y) in metres (none when empty)."""
    from ezdxf.entities.mtext import MText  # noqa: PLC0415

    text = entity.plain_text() if isinstance(entity, MText) else entity.dxf.text
    words = " ".join(str(text).split())
    at = entity.dxf.insert
    return [(words, (float(at.x) / per_metre, float(at.y) / per_metre))] if words else []


def _polyline(entity: LWPolyline | Polyline) -> tuple[FloatArray, bool]:
    """Return a polyline's (K, 2) vertices and whether it is closed."""
    from ezdxf.entities.lwpolyline import LWPolyline  # noqa: PLC0415

    if isinstance(entity, LWPolyline):
        xy = np.array(list(entity.vertices()), dtype=np.float64).reshape(-1, 2)
        return xy, bool(entity.closed)
    xyz = np.array([v.dxf.location.xyz for v in entity.vertices], dtype=np.float64)
    return xyz.reshape(-1, 3)[:, :2], bool(entity.is_closed)


def read_underlay(
    path: Path, *, units: Units = Units.M, up: UpAxis = UpAxis.FORMAT
) -> BuildingModel | FloorPlan:
    """Read a building model or, for a ``.dxf``, a floor plan (see :func:`section_segments`)."""
    if path.suffix.lower() == ".dxf":
        return read_floor_plan(path, units=units)
    return read_building(path, units=units, up=up)


def read_georeference(path: Path) -> tuple[SimilarityTransform, str] | None:
    """Return the site transform and CRS of an IFC file's ``IfcMapConversion``, if it has one.

    The IFC's own coordinates are taken as the evaluation frame, so the site transform is
    the map conversion: rotation ``atan2(XAxisOrdinate, XAxisAbscissa)`` about Z,
    translation (Eastings, Northings, OrthogonalHeight) and scale ``Scale`` times the
    project's and the map's units, all turned into metres.

    Raises:
        ExportOptionsError: a missing or unreadable IFC file.
    """
    model = _open_ifc(path)
    return _map_conversion(model)


def georeferenced_options(options: ExportOptions) -> ExportOptions:
    """Return the options with the site and CRS of an IFC building when they are not given.

    The building's map conversion is used only when the options give neither a CRS nor a
    site transform (the identity counts as not given): a site or CRS the user gives wins.

    Raises:
        ExportOptionsError: an IFC building that cannot be read.
    """
    building = options.building
    if building is None or building.suffix.lower() != ".ifc" or options.crs is not None:
        return options
    if not _is_identity(options.site):
        return options
    found = read_georeference(building)
    if found is None:
        return options
    site, crs = found
    return replace(options, site=site, crs=crs)


# --- the floor plan ------------------------------------------------------------------------


def section_segments(
    building: BuildingModel | FloorPlan,
    z_m: float,
    *,
    site: SimilarityTransform | None = None,
) -> FloatArray:
    """Cut a building horizontally at a height: its floor plan in the evaluation frame.

    A mesh is cut by the plane ``z = z_m`` of the evaluation frame (walls, columns and door
    leaves become their outlines); a floor plan's lines are used as they are. Either is
    mapped from model coordinates into the evaluation frame by the inverse of ``site``.

    Args:
        building: the building model or floor plan.
        z_m: height of the cut in the evaluation frame, metres (the device's height);
            ignored for a floor plan.
        site: evaluation frame -> model coordinates; by default the building's own (an
            IFC's map conversion), else the identity.

    Returns:
        (K, 2, 2) float64 segments ``[[x0, y0], [x1, y1]]``, evaluation-frame metres.
    """
    import trimesh  # noqa: PLC0415  (the section needs it, the module's readers may not)

    if site is None:
        site = getattr(building, "site", None) or SimilarityTransform.identity()
    to_frame = site.inverse()
    if isinstance(building, FloorPlan):
        ends = building.segments_m.reshape(-1, 2)
        xyz = np.column_stack([ends, np.zeros(len(ends))])
        out: FloatArray = to_frame.apply_positions(xyz)[:, :2].reshape(-1, 2, 2)
        return out
    mesh = trimesh.Trimesh(
        to_frame.apply_positions(building.vertices_m), building.faces, process=False
    )
    plane = ([0.0, 0.0, 1.0], [0.0, 0.0, float(z_m)])
    lines = trimesh.intersections.mesh_plane(mesh, *plane)  # type: ignore[no-untyped-call]
    section: FloatArray = np.asarray(lines, dtype=np.float64).reshape(-1, 2, 3)[:, :, :2]
    return section


# --- helpers -------------------------------------------------------------------------------


def _check_file(path: Path, suffixes: tuple[str, ...]) -> str:
    suffix = path.suffix.lower()
    if suffix not in suffixes:
        kinds = ", ".join(s.lstrip(".").upper() for s in suffixes)
        msg = f"The building model {str(path)!r} is not a supported file; export it as {kinds}."
        raise ExportOptionsError(msg, option="building")
    if not path.is_file():
        msg = f"The building model {str(path)!r} does not exist; check the path."
        raise ExportOptionsError(msg, option="building")
    return suffix


def _read_trimesh(path: Path, suffix: str) -> tuple[FloatArray, NDArray[np.int64]]:
    import trimesh  # noqa: PLC0415

    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as err:  # trimesh's many parsers raise anything
        msg = (
            f"The building model {str(path)!r} cannot be read as {suffix} ({err}); check the file."
        )
        raise ExportOptionsError(msg, option="building") from err
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        msg = f"The building model {str(path)!r} holds no triangles; export the model as a mesh."
        raise ExportOptionsError(msg, option="building")
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def _open_ifc(path: Path) -> ifcopenshell.file:
    import ifcopenshell  # noqa: PLC0415  (only an IFC building needs it)

    _check_file(path, (".ifc",))
    try:
        return ifcopenshell.open(str(path))
    except (OSError, RuntimeError, ValueError, ifcopenshell.Error) as err:
        msg = f"The building model {str(path)!r} cannot be read as IFC ({err}); check the file."
        raise ExportOptionsError(msg, option="building") from err


def _read_ifc(path: Path) -> BuildingModel:
    import ifcopenshell.geom  # noqa: PLC0415

    model = _open_ifc(path)
    settings = ifcopenshell.geom.settings()  # type: ignore[no-untyped-call]
    settings.set("use-world-coords", True)  # noqa: FBT003  (ifcopenshell's API)
    vertices: list[FloatArray] = []
    faces: list[NDArray[np.int64]] = []
    count = 0
    # spaces are rooms (their air), not building elements: they name places (spaces.py)
    iterator = ifcopenshell.geom.iterator(
        settings, model, 1, exclude=["IfcSpace", "IfcOpeningElement"]
    )
    if iterator.initialize():
        while True:  # one iteration per building element, not per vertex
            geometry = iterator.get().geometry  # type: ignore[no-untyped-call]
            v = np.asarray(geometry.verts, dtype=np.float64).reshape(-1, 3)
            f = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
            vertices.append(v)
            faces.append(f + count)
            count += len(v)
            if not iterator.next():
                break
    if not faces or count == 0:
        msg = (
            f"The building model {str(path)!r} has no element with a body geometry; "
            "export the IFC with its 3D bodies."
        )
        raise ExportOptionsError(msg, option="building")
    local_m = np.concatenate(vertices)  # ifcopenshell.geom gives metres, world coordinates
    found = _map_conversion(model)
    if found is None:
        return BuildingModel(local_m, np.concatenate(faces), path)
    site, crs = found
    return BuildingModel(
        site.apply_positions(local_m), np.concatenate(faces), path, site=site, crs=crs
    )


def _map_conversion(model: ifcopenshell.file) -> tuple[SimilarityTransform, str] | None:
    import ifcopenshell.util.unit  # noqa: PLC0415

    conversions = model.by_type("IfcMapConversion") if model.schema != "IFC2X3" else []
    if not conversions:
        return None
    conversion = conversions[0]
    target = conversion.TargetCRS
    project_m_per_unit = float(ifcopenshell.util.unit.calculate_unit_scale(model))
    map_m_per_unit = 1.0 if target.MapUnit is None else _metres_per_unit(target.MapUnit)
    a = conversion.XAxisAbscissa if conversion.XAxisAbscissa is not None else 1.0
    b = conversion.XAxisOrdinate if conversion.XAxisOrdinate is not None else 0.0
    yaw = math.atan2(float(b), float(a))
    rotation = np.array(
        [[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0, 0, 1.0]]
    )
    scale = 1.0 if conversion.Scale is None else float(conversion.Scale)
    height = conversion.OrthogonalHeight or 0.0
    translation = np.array([conversion.Eastings, conversion.Northings, height], dtype=np.float64)
    # local units -> map units (Scale), then both in metres; the evaluation frame is metres
    site = SimilarityTransform(
        rotation,
        translation * map_m_per_unit,
        scale * map_m_per_unit / project_m_per_unit,
    )
    return site, str(target.Name)


def _metres_per_unit(unit: ifcopenshell.entity_instance) -> float:
    """Return how many metres one of an IFC length unit (SI or conversion-based) is."""
    if unit.is_a("IfcSIUnit"):  # type: ignore[no-untyped-call]
        return _SI_PREFIX.get(unit.Prefix, 1.0)
    factor = unit.ConversionFactor  # IfcConversionBasedUnit: e.g. 0.3048 METRE per FOOT
    return float(factor.ValueComponent.wrappedValue) * _metres_per_unit(factor.UnitComponent)


def _is_identity(site: SimilarityTransform) -> bool:
    return bool(np.allclose(site.as_matrix(), np.eye(4), rtol=0.0, atol=1e-12))


def _arc(entity: Circle, *, full: bool) -> FloatArray:
    """Return (N, 2) points along a circle or arc, in 5° chords."""
    dxf = entity.dxf
    start = 0.0 if full else math.radians(dxf.start_angle)
    end = 2 * math.pi if full else math.radians(dxf.end_angle)
    if end <= start:
        end += 2 * math.pi
    count = max(2, math.ceil((end - start) / _ARC_SEGMENT_RAD) + 1)
    angles = np.linspace(start, end, count)
    cx, cy = dxf.center.x, dxf.center.y
    out: FloatArray = np.column_stack(
        [cx + dxf.radius * np.cos(angles), cy + dxf.radius * np.sin(angles)]
    )
    return out
