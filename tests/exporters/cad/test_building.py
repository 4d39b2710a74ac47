"""Building models in: IFC, meshes and DXF floor plans, their georeference and sections."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest

from exporters.cad.placement import parse_site, place_evaluation
from exporters.errors import ExportOptionsError
from exporters.options import ExportOptions, Units, UpAxis
from loceval.evaluation import EvaluationResult

trimesh = pytest.importorskip("trimesh")
ezdxf = pytest.importorskip("ezdxf")
ifcopenshell = pytest.importorskip("ifcopenshell")

from exporters.cad import building, dxf, gltf, ifc  # noqa: E402  (after the importorskip of its libraries)
from tests.exporters.cad.test_ifc import NAMES, assert_same_as_dxf  # noqa: E402
from tests.exporters.ifcfactory import DOOR_X_M, GRID_CONVERSION, GRID_YAW_DEG, write_room  # noqa: E402


@pytest.fixture
def room(tmp_path: Path) -> Path:
    """Return a georeferenced IFC of one room with a door."""
    return write_room(tmp_path / "room.ifc", map_conversion=GRID_CONVERSION)


def on_line(segments: np.ndarray, axis: int, value: float) -> np.ndarray:
    """Return the segments lying on the line ``coordinate[axis] == value``."""
    return segments[np.all(np.abs(segments[:, :, axis] - value) < 1e-6, axis=1)]


def test_ifc_gives_mesh_site_and_crs(room: Path) -> None:
    """An IFC's map conversion is the site; the mesh is in map coordinates, metres."""
    model = building.read_building(room)
    assert model.crs == "EPSG:25832"
    assert model.site is not None
    np.testing.assert_allclose(model.site.translation, [512340.0, 5403210.5, 112.3])
    assert model.site.scale == pytest.approx(1.0)  # 0.001 map metres per project millimetre
    yaw = math.degrees(math.atan2(model.site.rotation[1, 0], model.site.rotation[0, 0]))
    assert yaw == pytest.approx(GRID_YAW_DEG)
    # the room's south-west outer corner (-0.2, -0.2, 0) in the IFC's own metres, mapped
    corner = model.site.apply_positions(np.array([[-0.2, -0.2, 0.0]]))[0]
    assert np.min(np.linalg.norm(model.vertices_m - corner, axis=1)) < 1e-6
    assert model.faces.shape[1] == 3
    assert int(model.faces.max()) < len(model.vertices_m)


def test_section_is_the_floor_plan_in_the_evaluation_frame(room: Path) -> None:
    """At 1.2 m the cut shows the walls' outlines, the door leaf, and the door's gap."""
    segments = building.section_segments(building.read_building(room), 1.2)
    ends = segments.reshape(-1, 2)
    np.testing.assert_allclose(ends.min(axis=0), [-0.2, -0.2], atol=1e-6)
    np.testing.assert_allclose(ends.max(axis=0), [6.2, 4.2], atol=1e-6)
    # the south wall's inner face (y = 0) is drawn west and east of the door, not across it
    inner = on_line(segments, 1, 0.0)
    xs = np.sort(inner[:, :, 0], axis=1)
    assert len(inner) > 0
    assert np.all((xs[:, 1] <= DOOR_X_M[0] + 1e-6) | (xs[:, 0] >= DOOR_X_M[1] - 1e-6))
    # the door leaf (y -0.125 .. -0.075) is drawn across the gap at 1.2 m ...
    leaf = on_line(segments, 1, -0.075)
    assert np.sort(leaf[:, :, 0], axis=1).min() == pytest.approx(DOOR_X_M[0])
    assert np.sort(leaf[:, :, 0], axis=1).max() == pytest.approx(DOOR_X_M[1])
    # ... and not above its 2.1 m height
    high = building.section_segments(building.read_building(room), 2.5)
    assert len(on_line(high, 1, -0.075)) == 0
    assert len(high) > 0


def test_section_with_another_site(room: Path) -> None:
    """A site given explicitly replaces the IFC's own: the cut is mapped by its inverse."""
    model = building.read_building(room)
    assert model.site is not None
    shifted = parse_site("512340.0 5403210.5 112.3 30")
    segments = building.section_segments(
        model, 1.2 + 0.5, site=shifted.compose(parse_site("0 0 -0.5 0"))
    )
    np.testing.assert_allclose(segments.reshape(-1, 2).min(axis=0), [-0.2, -0.2], atol=1e-6)


def test_ifc_building_places_the_paths(room: Path, two_estimates: EvaluationResult) -> None:
    """Without a site, an IFC building's georeference places the paths in every CAD file."""
    options = ExportOptions(building=room)
    resolved = building.georeferenced_options(options)
    assert resolved.crs == "EPSG:25832"
    np.testing.assert_allclose(resolved.site.translation, [512340.0, 5403210.5, 112.3])
    placement = place_evaluation(two_estimates, options)
    expected = resolved.site.apply_positions(two_estimates.reference.positions_xyz[:1]) * 1000.0
    np.testing.assert_allclose(placement.paths[0].vertices[0], expected[0], atol=1e-6)
    model = ifcopenshell.file.from_string(ifc.export_ifc(two_estimates, options).decode())
    (conversion,) = model.by_type("IfcMapConversion")
    assert (conversion.Eastings, conversion.Northings) == (512340.0, 5403210.5)
    assert conversion.XAxisOrdinate == pytest.approx(0.5)
    assert conversion.TargetCRS.Name == "EPSG:25832"
    # the paths in the IFC, mapped by its conversion, are the DXF's (placed the same way)
    assert_same_as_dxf(model, dxf.export_dxf(two_estimates, options), resolved, NAMES)


def test_given_site_or_crs_wins(room: Path) -> None:
    """A site or CRS the user gives is kept; only the identity counts as not given."""
    site = parse_site("10 20 0 0")
    options = ExportOptions(building=room, site=site)
    assert building.georeferenced_options(options) is options
    with_crs = ExportOptions(building=room, crs="EPSG:31467")
    assert building.georeferenced_options(with_crs) is with_crs


def test_ifc_without_georeference(tmp_path: Path) -> None:
    """An IFC without a map conversion is a mesh in its own metres, with no site."""
    model = building.read_building(write_room(tmp_path / "plain.ifc"))
    assert model.site is None
    assert model.crs is None
    np.testing.assert_allclose(model.vertices_m.min(axis=0), [-0.2, -0.2, 0.0], atol=1e-6)
    np.testing.assert_allclose(model.vertices_m.max(axis=0), [6.2, 4.2, 3.0], atol=1e-6)
    assert building.read_georeference(tmp_path / "plain.ifc") is None


@pytest.mark.parametrize(
    ("up", "suffix"), [(UpAxis.Z, ".obj"), (UpAxis.Y, ".obj"), (UpAxis.Z, ".ply")]
)
def test_meshes_units_and_up_axis(tmp_path: Path, up: UpAxis, suffix: str) -> None:
    """OBJ/PLY are read in the given units, Z up, or Y up turned to Z up."""
    box = trimesh.creation.box(extents=(4.0, 3.0, 2.5))
    box.apply_translation([10.0, 20.0, 1.25])  # Z-up metres: x 8..12, y 18.5..21.5, z 0..2.5
    vertices_mm = np.asarray(box.vertices) * 1000.0
    if up is UpAxis.Y:  # as a Y-up exporter writes it: (x, y, z) -> (x, z, -y)
        vertices_mm = vertices_mm @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T
    path = tmp_path / f"box{suffix}"
    trimesh.Trimesh(vertices_mm, box.faces).export(path)
    model = building.read_building(path, units=Units.MM, up=up)
    np.testing.assert_allclose(model.vertices_m.min(axis=0), [8.0, 18.5, 0.0], atol=1e-6)
    np.testing.assert_allclose(model.vertices_m.max(axis=0), [12.0, 21.5, 2.5], atol=1e-6)
    square = building.section_segments(model, 1.0)
    np.testing.assert_allclose(square.reshape(-1, 2).min(axis=0), [8.0, 18.5], atol=1e-6)


def test_glb_is_metres_y_up(tmp_path: Path) -> None:
    """A GLB building follows glTF: metres, Y up."""
    box = trimesh.creation.box(extents=(4.0, 3.0, 2.5))
    box.apply_translation([0.0, 0.0, 1.25])
    path = tmp_path / "box.glb"
    y_up = np.asarray(box.vertices) @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T
    trimesh.Trimesh(y_up, box.faces).export(path)
    model = building.read_building(path, units=Units.MM)
    np.testing.assert_allclose(model.vertices_m.min(axis=0), [-2.0, -1.5, 0.0], atol=1e-6)


def test_dxf_floor_plan(tmp_path: Path) -> None:
    """A DXF's lines, polylines and arcs become segments in metres, in the evaluation frame."""
    doc = ezdxf.new("R2013", units=ezdxf.units.MM)
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (6000, 0), (6000, 4000), (0, 4000)], close=True)
    msp.add_line((3000, 0), (3000, 4000))
    msp.add_arc((3000, 2000), radius=500, start_angle=0, end_angle=90)
    path = tmp_path / "plan.dxf"
    doc.saveas(path)
    plan = building.read_underlay(path)
    assert isinstance(plan, building.FloorPlan)
    # 4 polyline sides + 1 line + 18 chords of 5° for the quarter arc
    assert plan.segments_m.shape == (23, 2, 2)
    np.testing.assert_allclose(plan.segments_m.reshape(-1, 2).max(axis=0), [6.0, 4.0])
    site = parse_site("100 200 0 90")  # the evaluation frame's x is the model's y
    segments = building.section_segments(plan, 0.0, site=site)
    # model (6, 4) is evaluation (4 - 200, -(6 - 100)) = (-196, 94)
    ends = segments.reshape(-1, 2)
    assert np.min(np.linalg.norm(ends - [-196.0, 94.0], axis=1)) < 1e-9


def test_glb_scene_takes_an_ifc_building(room: Path, two_estimates: EvaluationResult) -> None:
    """The GLB reads an IFC building through the same loader, in the same coordinates."""
    data = gltf.export_glb(two_estimates, ExportOptions(building=room))
    scene = trimesh.load(io.BytesIO(data), file_type="glb")
    meshes = [k for k, g in scene.geometry.items() if isinstance(g, trimesh.Trimesh)]
    assert meshes == ["building"]  # beside it the paths, as Path3D (issue 44, item 12)
    mesh = scene.geometry["building"]
    assert len(mesh.faces) == len(building.read_building(room).faces)


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("missing.ifc", None, "does not exist"),
        ("model.fbx", b"FBX", "is not a supported file"),
        ("broken.ifc", b"ISO-10303-21;\nnonsense\n", "cannot be read as IFC"),
        ("empty.obj", b"# nothing\n", "cannot be read|holds no triangles"),
    ],
)
def test_bad_building(tmp_path: Path, name: str, content: bytes | None, match: str) -> None:
    """A missing, unsupported or unreadable building is an options error about the building."""
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(ExportOptionsError, match=rf"building model .*{name}.* ({match})") as info:
        building.read_building(path)
    assert info.value.option == "building"


def test_ifc_without_bodies(tmp_path: Path) -> None:
    """An IFC with no element geometry says to export its 3D bodies."""
    path = tmp_path / "empty.ifc"
    f = ifcopenshell.file(schema="IFC4")
    f.create_entity("IfcProject", GlobalId=ifcopenshell.guid.new(), Name="empty")
    f.write(str(path))
    with pytest.raises(ExportOptionsError, match="has no element with a body geometry"):
        building.read_building(path)


def test_dxf_without_lines(tmp_path: Path) -> None:
    """A floor plan without lines says what to export."""
    path = tmp_path / "blank.dxf"
    ezdxf.new("R2013").saveas(path)
    with pytest.raises(ExportOptionsError, match="has no lines in its model space"):
        building.read_floor_plan(path)
