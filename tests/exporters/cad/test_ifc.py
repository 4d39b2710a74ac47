"""IFC export: validate with ifcopenshell, read back, compare with the DXF."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest

from exporters import ARTIFACTS, CAD_ARTIFACTS
from exporters.cad.placement import parse_site
from exporters.errors import ExportOptionsError
from exporters.options import ExportOptions, Units
from loceval.core.geometry import SimilarityTransform
from loceval.evaluation import AlignMethod, EvaluationConfig, EvaluationResult, evaluate
from loceval.readers import read_trajectory
from tests.exporters.conftest import noisy, walk

pytest.importorskip("ifcopenshell")
ezdxf = pytest.importorskip("ezdxf")
import ifcopenshell  # noqa: E402  (after the importorskip of its library)
import ifcopenshell.validate  # noqa: E402

from exporters.cad import dxf, ifc  # noqa: E402

# ifcopenshell's EXPRESS-rule loader leaves its generated rules file open
pytestmark = pytest.mark.filterwarnings(
    r"ignore:Exception ignored in. <_io.FileIO name='.*ifcopenshell"
    ":pytest.PytestUnraisableExceptionWarning"
)

SITE = "512340.0 5403210.5 112.3 37.5"
NAMES = ["OptiTrack", "RTAB-Map", "ISAAC"]


def read_ifc(data: bytes) -> ifcopenshell.file:
    """Parse IFC bytes with ifcopenshell."""
    return ifcopenshell.file.from_string(data.decode("utf-8"))


def assert_valid(model: ifcopenshell.file, *, express_rules: bool = False) -> None:
    """The model passes ifcopenshell's schema (and, if asked, EXPRESS-rule) validation."""
    # the EXPRESS rules take about 20 s per model on this machine: checked once, below
    logger = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(model, logger, express_rules=express_rules)
    assert logger.statements == []


def dxf_paths(data: bytes) -> dict[str, np.ndarray]:
    """Return the vertices of each trajectory's 3D POLYLINEs of a DXF, joined, by layer.

    A trajectory is one POLYLINE per continuous piece (it breaks at tracking loss); the
    pieces are joined in file order, as :func:`pieces` joins the IFC's curves.
    """
    doc = ezdxf.read(io.StringIO(data.decode("utf-8")))
    parts: dict[str, list[np.ndarray]] = {}
    for polyline in doc.modelspace().query("POLYLINE"):
        if polyline.dxf.layer.endswith(" ATE"):
            continue
        vertices = np.array([v.dxf.location.xyz for v in polyline.vertices])
        parts.setdefault(polyline.dxf.layer, []).append(vertices)
    return {layer: np.concatenate(found) for layer, found in parts.items()}


def trajectories(model: ifcopenshell.file) -> dict[str, ifcopenshell.entity_instance]:
    """Return the trajectory annotations by name."""
    return {
        a.Name: a for a in model.by_type("IfcAnnotation") if a.ObjectType == ifc.TRAJECTORY_TYPE
    }


def pieces(annotation: ifcopenshell.entity_instance) -> list[np.ndarray]:
    """Return the (M, 3) coordinates of each curve of an annotation, in file coordinates."""
    (representation,) = annotation.Representation.Representations
    return [
        np.array(item.Points.CoordList)
        if item.is_a("IfcIndexedPolyCurve")
        else np.array([item.Coordinates])
        for item in representation.Items
    ]


def apply_map_conversion(model: ifcopenshell.file, local: np.ndarray) -> np.ndarray:
    """Apply the file's IfcMapConversion (IFC4 definition) to (N, 3) coordinates."""
    (conversion,) = model.by_type("IfcMapConversion")
    scale = conversion.Scale
    a, b = conversion.XAxisAbscissa, conversion.XAxisOrdinate
    norm = math.hypot(a, b)
    cos, sin = a / norm, b / norm
    x, y, z = local.T
    return np.stack(
        [
            conversion.Eastings + scale * (cos * x - sin * y),
            conversion.Northings + scale * (sin * x + cos * y),
            conversion.OrthogonalHeight + scale * z,
        ],
        axis=1,
    )


def property_set(element: ifcopenshell.entity_instance, name: str) -> dict[str, object]:
    """Return the values of one property set of an element."""
    for rel in element.IsDefinedBy:
        pset = rel.RelatingPropertyDefinition
        if pset.Name == name:
            return {p.Name: p.NominalValue.wrappedValue for p in pset.HasProperties}
    raise AssertionError(name)


def assert_same_as_dxf(
    model: ifcopenshell.file, dxf_data: bytes, options: ExportOptions, names: list[str]
) -> None:
    """Each trajectory's curves, joined (and mapped), are its DXF polyline within 1 mm."""
    expected = dxf_paths(dxf_data)
    found = trajectories(model)
    assert sorted(found) == sorted(names)
    per_mm = options.units.per_metre / 1000.0
    for name in names:
        local = np.concatenate([c for c in pieces(found[name]) if len(c) >= 2])  # DXF: curves only
        if options.crs is not None:
            placed = apply_map_conversion(model, local) * options.units.per_metre
        else:
            placed = local
        assert placed.shape == expected[name].shape
        assert np.abs(placed - expected[name]).max() <= 1.0 * per_mm


@pytest.fixture
def crs_options() -> ExportOptions:
    """Return millimetre options with a national-grid site and a CRS."""
    return ExportOptions(
        site=parse_site(SITE), crs="EPSG:25832", evaluation_id="ev-7", title="Lab run"
    )


def test_registered_as_cad_artifact() -> None:
    """paths.ifc is a lazily loaded CAD artifact served as application/x-step."""
    spec = ARTIFACTS["paths.ifc"]
    assert spec.media_type == "application/x-step"
    assert spec.load() is ifc.export_ifc
    assert "paths.ifc" in CAD_ARTIFACTS


def test_georeferenced_round_trip(
    two_estimates: EvaluationResult, crs_options: ExportOptions
) -> None:
    """With a CRS the file validates, keeps evaluation-frame coordinates and maps onto the DXF."""
    model = read_ifc(ifc.export_ifc(two_estimates, crs_options))
    assert_valid(model, express_rules=True)
    assert model.schema == "IFC4"
    assert_same_as_dxf(model, dxf.export_dxf(two_estimates, crs_options), crs_options, NAMES)
    (conversion,) = model.by_type("IfcMapConversion")
    # the site as given: "512340.0 5403210.5 112.3 37.5" (metres, degrees)
    assert conversion.Eastings == 512340.0
    assert conversion.Northings == 5403210.5
    assert conversion.OrthogonalHeight == pytest.approx(112.3, abs=1e-12)
    assert conversion.XAxisAbscissa == pytest.approx(math.cos(math.radians(37.5)), abs=1e-12)
    assert conversion.XAxisOrdinate == pytest.approx(math.sin(math.radians(37.5)), abs=1e-12)
    assert conversion.Scale == pytest.approx(0.001)  # millimetres in the file, metres in the map
    assert conversion.TargetCRS.Name == "EPSG:25832"
    assert conversion.TargetCRS.MapUnit.Name == "METRE"
    # the file's own coordinates stay in the evaluation frame: the walk spans about ±6 m
    local = np.concatenate(pieces(trajectories(model)["OptiTrack"]))
    assert np.abs(local[:, :2]).max() < 7000.0
    np.testing.assert_allclose(
        local[0], two_estimates.reference.positions_xyz[0] * 1000.0, atol=1e-6
    )


@pytest.mark.parametrize(("units", "prefix"), [(Units.M, None), (Units.CM, "CENTI")])
def test_without_crs_model_coordinates(
    two_estimates: EvaluationResult, units: Units, prefix: str | None
) -> None:
    """Without a CRS the vertices are the DXF's model coordinates, in the output units."""
    options = ExportOptions(units=units, site=parse_site("2000.25 -1500.5 12.3 30"))
    model = read_ifc(ifc.export_ifc(two_estimates, options))
    assert_valid(model)
    assert model.by_type("IfcMapConversion") == ()
    (length,) = [u for u in model.by_type("IfcSIUnit") if u.UnitType == "LENGTHUNIT"]
    assert (length.Prefix, length.Name) == (prefix, "METRE")
    assert_same_as_dxf(model, dxf.export_dxf(two_estimates, options), options, NAMES)


def test_properties_and_colours(
    two_estimates: EvaluationResult, crs_options: ExportOptions
) -> None:
    """Each path carries its ATE/RPE statistics and verdict, and its palette colour."""
    model = read_ifc(ifc.export_ifc(two_estimates, crs_options))
    found = trajectories(model)
    for est in two_estimates.estimates:
        values = property_set(found[est.name], "Loceval_Path")
        assert values["Kind"] == "estimate"
        assert values["ATE_translation_rmse_m"] == est.ate_translation.stats.rmse
        assert values["ATE_translation_max_m"] == est.ate_translation.stats.max
        assert values["RPE_translation_rmse_m"] == est.rpe_translation.stats.rmse
        assert values["ATE_translation_n"] == est.ate_translation.stats.n
        assert est.verdict is not None
        assert values["Verdict"] == ("PASS" if est.verdict.passed else "FAIL")
    reference = property_set(found["OptiTrack"], "Loceval_Path")
    assert reference["Kind"] == "reference"
    assert "Verdict" not in reference
    (project,) = model.by_type("IfcProject")
    assert property_set(project, "Loceval_Evaluation")["EvaluationId"] == "ev-7"
    (curve,) = pieces_items(found["RTAB-Map"])
    (styled,) = curve.StyledByItem
    colour = styled.Styles[0].CurveColour
    assert (colour.Red, colour.Green, colour.Blue) == (1.0, 0.0, 1.0)  # magenta, palette 1


def pieces_items(annotation: ifcopenshell.entity_instance) -> list[ifcopenshell.entity_instance]:
    """Return the representation items of an annotation."""
    (representation,) = annotation.Representation.Representations
    return list(representation.Items)


def test_split_at_tracking_loss(rng: np.random.Generator) -> None:
    """A 3 s hole in the reference cuts its annotation into two curves and marks the loss."""
    truth = walk(rng)
    hole = (np.arange(len(truth)) < 2000) | (np.arange(len(truth)) >= 2300)
    estimate = noisy(rng, truth, every=3, sigma=0.02, drift=0.0, name="VIO")
    result = evaluate(truth.select(hole), [estimate], EvaluationConfig())
    options = ExportOptions(simplify_m=0.0)
    model = read_ifc(ifc.export_ifc(result, options))
    assert_valid(model)
    curves = pieces(trajectories(model)["OptiTrack"])
    # poses 0..1999 and 2300..5999 of the 6000-pose walk, every pose kept (simplify 0)
    assert [len(c) for c in curves] == [2000, 3700]
    np.testing.assert_allclose(curves[1][0], truth.positions_xyz[2300] * 1000.0, rtol=0, atol=1e-6)
    losses = [a for a in model.by_type("IfcAnnotation") if a.ObjectType == "tracking loss"]
    # one marker per real tracking loss, not one per trajectory that inherits the hole
    assert sorted(a.Name for a in losses) == ["no pose for 3.0 s from t=20.0 s"]
    assert_same_as_dxf(model, dxf.export_dxf(result, options), options, ["OptiTrack", "VIO"])
    worst = [a for a in model.by_type("IfcAnnotation") if a.ObjectType == "greatest error"]
    assert worst
    assert all(len(pieces_items(a)) == 2 for a in worst)  # the point and the line to the truth


def test_bad_crs_is_refused() -> None:
    """A CRS that is not AUTHORITY:CODE names the value and the form to use."""
    with pytest.raises(ExportOptionsError, match=r"'25832' is not of the form") as info:
        ExportOptions(crs="25832")
    assert info.value.option == "crs"


def test_tilted_site_with_crs_is_refused(two_estimates: EvaluationResult) -> None:
    """A map conversion turns only about the vertical: a tilted site with a CRS is an error."""
    tilt = SimilarityTransform.from_matrix(
        np.array([[1, 0, 0, 5.0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)
    )
    options = ExportOptions(site=tilt, crs="EPSG:25832")
    with pytest.raises(ExportOptionsError, match="tilts the evaluation frame") as info:
        ifc.export_ifc(two_estimates, options)
    assert info.value.option == "site"


@pytest.mark.public_data
@pytest.mark.parametrize(
    ("reference", "estimate", "align"),
    [
        ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", AlignMethod.SIM3),
        ("nav2_turtlebot.mcap@/amcl_pose", "nav2_turtlebot.mcap@/odom", AlignMethod.SE3),
    ],
)
def test_public_recordings(
    public_data: Path, crs_options: ExportOptions, reference: str, estimate: str, align: AlignMethod
) -> None:
    """fr2_desk and the nav2 MCAP: valid IFC, one annotation each, the DXF's vertices."""
    result = evaluate(
        read_trajectory(str(public_data / reference), name="ground truth"),
        [read_trajectory(str(public_data / estimate), name="estimate")],
        EvaluationConfig(align=align),
    )
    model = read_ifc(ifc.export_ifc(result, crs_options))
    assert_valid(model)
    dxf_data = dxf.export_dxf(result, crs_options)
    assert_same_as_dxf(model, dxf_data, crs_options, ["ground truth", "estimate"])
    vertex_counts = {n: len(v) for n, v in dxf_paths(dxf_data).items()}
    for name, annotation in trajectories(model).items():
        values = property_set(annotation, "Loceval_Path")
        found = pieces(annotation)
        assert values["Vertices"] == sum(len(c) for c in found)
        # every vertex of a curve is the DXF's; the IFC also keeps lone poses as points
        assert sum(len(c) for c in found if len(c) >= 2) == vertex_counts[name]
