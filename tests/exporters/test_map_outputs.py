"""The map and the excursions in the outputs: map_cells.csv, the DXF layers, the report."""

from __future__ import annotations

import io
import re
from dataclasses import replace

import numpy as np
import pytest

from exporters import ExportOptions, render_artifact
from exporters.plots.mapplan import MAP_FIGURE_KEY, plot_map
from exporters.report.mapsection import build_map_view
from loceval.core.geometry import SimilarityTransform
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from loceval.maps import evaluate_map
from loceval.registration.alignment import AlignWindow
from tests.loceval.metrics.test_excursions import _run
from tests.mapfactory import Distortion, draw_map, office_plan

ezdxf = pytest.importorskip("ezdxf")


@pytest.fixture(scope="module", name="result")
def _result() -> EvaluationResult:
    """An evaluation with one excursion and a map 1.2 % short with two clutter blobs."""
    reference, estimate, _ = _run()
    config = EvaluationConfig(align_first=AlignWindow.parse("19s"), no_ci=True)
    result = evaluate(reference, [estimate], config)
    plan = office_plan()
    grid = draw_map(
        plan,
        Distortion(scale=0.988),
        resolution_m=0.05,
        rng=np.random.default_rng(5),
        clutter_xy=np.array([[3.0, 8.0], [12.5, 9.5]]),
    )
    found = evaluate_map(grid, plan, SimilarityTransform.identity(), estimate="slam")
    return replace(result, map=found)


def test_map_cells_csv_lists_every_wall_cell(result: EvaluationResult) -> None:
    """One row per wall cell: placed x, y, both distances and the clutter flag."""
    text = render_artifact("map_cells.csv", result, ExportOptions()).decode()
    lines = text.splitlines()
    assert lines[0] == "x_m,y_m,distance_m,fitted_distance_m,clutter"
    table = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1)
    found = result.map
    assert found is not None
    assert len(table) == len(found.cells_xy)
    np.testing.assert_allclose(table[:, 2], found.distance_m, atol=1e-5)
    assert int(table[:, 4].sum()) == found.clutter_cells


def test_map_cells_csv_without_a_map_says_so(result: EvaluationResult) -> None:
    """No map: the header and a comment naming what to give."""
    text = render_artifact("map_cells.csv", replace(result, map=None), ExportOptions()).decode()
    assert text.splitlines()[1].startswith("# no map was measured")


def test_the_dxf_has_map_and_excursion_layers(result: EvaluationResult) -> None:
    """map plan lines, map wall and clutter points, the excursion path and its label."""
    data = render_artifact("paths.dxf", result, ExportOptions(units="m"))
    doc = ezdxf.read(io.StringIO(data.decode()))
    msp = doc.modelspace()
    found = result.map
    assert found is not None
    assert len(msp.query('LINE[layer=="map plan"]')) == len(found.plan_xy)
    walls = len(msp.query('POINT[layer=="map walls"]'))
    clutter = len(msp.query('POINT[layer=="map clutter"]'))
    assert walls + clutter == len(found.cells_xy)
    assert clutter == found.clutter_cells
    (label,) = msp.query('TEXT[layer=="excursions"]')
    assert label.dxf.text == "slam excursion: 45 s, 45 m, error 0.00 → 0.22 m"
    assert len(msp.query('POLYLINE[layer=="excursions"]')) == 1


def test_the_report_has_the_map_figure_and_section(result: EvaluationResult) -> None:
    """The figure is drawn and the section's rows say placed, rigid and similarity."""
    (plot,) = plot_map(result, formats=("svg",))
    assert plot.key == MAP_FIGURE_KEY
    assert b"<svg" in (plot.svg or b"")
    # 1.2 % within the cells' quantisation (a half cell at a wall is 0.1 % of 20 m)
    assert re.search(r"the map is 1\.[23] % short", plot.caption)
    view = build_map_view(result)
    assert view is not None
    assert [row["name"] for row in view.rows] == ["as placed", "rigid fit", "similarity fit"]
    assert view.drift in plot.caption
    assert view.axis_scales is not None
    assert view.axis_scales.startswith("per axis of the map (its x axis at 0.0° on the plan)")
    assert build_map_view(replace(result, map=None)) is None


def test_the_3dm_has_the_map_as_coloured_point_clouds(result: EvaluationResult) -> None:
    """One point cloud per distance bin and one of clutter, every wall cell in one of them."""
    rhino3dm = pytest.importorskip("rhino3dm")
    model = rhino3dm.File3dm.FromByteArray(render_artifact("paths.3dm", result, ExportOptions()))
    clouds = [o for o in model.Objects if isinstance(o.Geometry, rhino3dm.PointCloud)]
    found = result.map
    assert found is not None
    assert sum(len(o.Geometry) for o in clouds) == len(found.cells_xy)
    (clutter,) = [o for o in clouds if o.Attributes.Name == "map clutter"]
    assert len(clutter.Geometry) == found.clutter_cells


def test_the_glb_has_the_map_as_coloured_points(result: EvaluationResult, validate) -> None:
    """A ``map walls`` node: one POINTS primitive, a colour per wall cell; the GLB is valid."""
    pygltflib = pytest.importorskip("pygltflib")
    data = render_artifact("paths.glb", result, ExportOptions())
    assert validate(data)["issues"]["numErrors"] == 0
    gltf = pygltflib.GLTF2.load_from_bytes(data)
    (node,) = [n for n in gltf.nodes if n.name == "map walls"]
    (primitive,) = gltf.meshes[node.mesh].primitives
    assert primitive.mode == pygltflib.POINTS
    found = result.map
    assert found is not None
    assert gltf.accessors[primitive.attributes.POSITION].count == len(found.cells_xy)
    assert gltf.accessors[primitive.attributes.COLOR_0].count == len(found.cells_xy)


@pytest.mark.filterwarnings(  # ifcopenshell's EXPRESS-rule loader leaves its rules file open
    r"ignore:Exception ignored in. <_io.FileIO name='.*ifcopenshell"
    ":pytest.PytestUnraisableExceptionWarning"
)
def test_the_ifc_has_the_map_and_excursions_and_validates(result: EvaluationResult) -> None:
    """paths.ifc: the plan's walls, the wall cells per bin and clutter, the excursion; valid.

    ifcopenshell's validator (schema and EXPRESS rules) reports nothing; the plan has one
    curve per wall segment, the clouds together hold every wall cell (fewer than the CAD
    cap here), the clutter cloud the clutter count, and the excursion its label and figures.
    """
    pytest.importorskip("ifcopenshell")
    import ifcopenshell.util.element
    import ifcopenshell.validate

    data = render_artifact("paths.ifc", result, ExportOptions(units="m"))
    model = ifcopenshell.file.from_string(data.decode())
    logger = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(model, logger, express_rules=True)
    assert logger.statements == []
    found = result.map
    assert found is not None
    by_type: dict[str, list[object]] = {}
    for annotation in model.by_type("IfcAnnotation"):
        by_type.setdefault(annotation.ObjectType, []).append(annotation)
    (plan,) = by_type["map plan"]
    (shape,) = plan.Representation.Representations
    assert len(shape.Items) == len(found.plan_xy)
    ends = np.array(shape.Items[0].Points.CoordList)
    assert ends.shape == (2 * len(found.plan_xy), 3)
    np.testing.assert_allclose(ends[:, :2].reshape(-1, 2, 2), found.plan_xy, atol=1e-6)
    figures = ifcopenshell.util.element.get_psets(plan)["Loceval_Map"]
    assert figures["WallDistance_rmse"] == pytest.approx(found.placed.rmse)
    assert figures["similarity_scale"] == pytest.approx(found.similarity[0].scale)
    assert found.axis_scales is not None
    assert figures["axis_scale_x"] == pytest.approx(found.axis_scales.scale_x)
    clouds = {a.Name: a.Representation.Representations[0] for a in by_type["map walls"]}
    assert {s.RepresentationType for s in clouds.values()} == {"PointCloud"}
    counts = {name: len(s.Items[0].CoordList) for name, s in clouds.items()}
    assert sum(counts.values()) == len(found.cells_xy)
    assert counts["map clutter"] == found.clutter_cells
    (excursion,) = by_type["excursion"]
    assert excursion.Name == "slam excursion: 45 s, 45 m, error 0.00 → 0.22 m"
    drift = ifcopenshell.util.element.get_psets(excursion)["Loceval_Excursion"]
    (expected,) = result.estimates[0].excursions
    assert drift["DriftPerMetre"] == pytest.approx(expected.drift_per_m)
    curve = excursion.Representation.Representations[0].Items[0]
    assert len(curve.Points.CoordList) >= 2


def test_the_3dm_and_glb_mark_the_excursion_like_the_dxf(result: EvaluationResult) -> None:
    """The same path and label as the DXF: a 3DM curve and text dot, a GLB line strip."""
    rhino3dm = pytest.importorskip("rhino3dm")
    pygltflib = pytest.importorskip("pygltflib")
    options = ExportOptions(units="m")
    doc = ezdxf.read(io.StringIO(render_artifact("paths.dxf", result, options).decode()))
    (polyline,) = doc.modelspace().query('POLYLINE[layer=="excursions"]')
    dxf_xyz = np.array([v.dxf.location for v in polyline.vertices])
    label = "slam excursion: 45 s, 45 m, error 0.00 → 0.22 m"

    model = rhino3dm.File3dm.FromByteArray(render_artifact("paths.3dm", result, options))
    (layer,) = [k for k, layer in enumerate(model.Layers) if layer.Name == "excursions"]
    mine = [o for o in model.Objects if o.Attributes.LayerIndex == layer]
    (curve,) = [o for o in mine if isinstance(o.Geometry, rhino3dm.PolylineCurve)]
    (dot,) = [o for o in mine if isinstance(o.Geometry, rhino3dm.TextDot)]
    assert dot.Geometry.Text == label == curve.Attributes.Name
    points = curve.Geometry.ToPolyline()
    rhino_xyz = np.array([[points[i].X, points[i].Y, points[i].Z] for i in range(points.Count)])
    np.testing.assert_allclose(rhino_xyz, dxf_xyz, atol=1e-9)

    gltf = pygltflib.GLTF2.load_from_bytes(render_artifact("paths.glb", result, options))
    (node,) = [n for n in gltf.nodes if n.name == "excursions"]
    (primitive,) = gltf.meshes[node.mesh].primitives
    assert primitive.mode == pygltflib.LINES
    assert gltf.accessors[primitive.attributes.POSITION].count == len(dxf_xyz)
    (record,) = node.extras["excursions"]
    assert record["label"] == label
    assert record["duration_s"] == pytest.approx(45.0, abs=0.5)


def test_the_viewer_scene_has_the_excursion_the_dxf_draws(result: EvaluationResult) -> None:
    """scene.py's ``excursions``: the DXF's vertices (local + base), label and figures."""
    from exporters.viewer.scene import viewer_scene

    options = ExportOptions(units="m")
    doc = ezdxf.read(io.StringIO(render_artifact("paths.dxf", result, options).decode()))
    (polyline,) = doc.modelspace().query('POLYLINE[layer=="excursions"]')
    dxf_xyz = np.array([v.dxf.location for v in polyline.vertices])
    scene = viewer_scene(result, options)
    (shown,) = scene["excursions"]  # type: ignore[misc]
    assert shown["path"] == 1
    assert shown["label"] == "slam excursion: 45 s, 45 m, error 0.00 → 0.22 m"
    xyz = np.array(shown["xyz"]).reshape(-1, 3) + np.array(scene["base"])
    np.testing.assert_allclose(xyz, dxf_xyz, atol=1e-4)  # the viewer rounds to 0.1 mm
    assert shown["drift_per_m"] == result.estimates[0].excursions[0].drift_per_m


def test_the_report_shows_the_map_over_time(
    result: EvaluationResult, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """A bag topic's messages: one table row each (the unjudged one with its reason), a plot."""
    from exporters.plots.mapplan import MAP_HISTORY_KEY, plot_map_history
    from loceval.maps import OccupancyGrid, evaluate_map_source
    from tests.mapfactory import write_map_bag

    plan = office_plan()
    rng = np.random.default_rng(3)
    grids = [
        (s, draw_map(plan, Distortion(scale=k), resolution_m=0.05, rng=rng))
        for s, k in ((30, 0.995), (60, 0.99))
    ]
    empty = OccupancyGrid(np.full(grids[0][1].shape, -1, dtype=np.int8), 0.05)
    bag = write_map_bag(tmp_path_factory.mktemp("bag"), [(10, empty), *grids])
    t0 = int(result.reference.stamps_ns[0])
    found = evaluate_map_source(f"{bag}@/map", plan, SimilarityTransform.identity(), t0_ns=t0)
    with_history = replace(result, map=found)
    view = build_map_view(with_history)
    assert view is not None
    assert [row["index"] for row in view.history] == ["0", "1", "2"]
    assert "no occupied cell" in view.history[0]["note"]
    assert view.history[2]["scale"] == f"{found.scale_error_pct:+.2f}"
    (plot,) = plot_map_history(with_history)
    assert plot.key == MAP_HISTORY_KEY
    assert b"<svg" in (plot.svg or b"")
    assert "2 map messages" in plot.caption
    html = render_artifact("report.html", with_history, ExportOptions()).decode()
    assert "The map over time" in html
    assert html.count('<tr class="strong">') == 1
    assert plot_map_history(result) == ()  # a map file: no history, no figure
