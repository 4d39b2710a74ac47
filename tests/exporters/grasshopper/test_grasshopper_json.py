"""The 3DM-compatible JSON the Grasshopper script reads: decode every curve with rhino3dm."""

from __future__ import annotations

import ast
import json

import numpy as np
import pytest

from exporters.cad.placement import parse_site
from exporters.options import ExportOptions, Units
from loceval.core.polyline import polyline_distances
from loceval.evaluation import EvaluationResult
from tests.exporters.conftest import (
    GRASSHOPPER_SCRIPT,
    curve_vertices,
    expected_paths,
    grasshopper_script_keys,
    with_reference_loss,
)

rhino3dm = pytest.importorskip("rhino3dm")
from exporters.cad import rhino  # noqa: E402  (after the importorskip of its library)

SITE = "512340.25 5403210.5 112.3 37.5"


def decode(entry: dict) -> np.ndarray:
    """Decode a path's curves with CommonObject.Decode and return their vertices, joined."""
    return np.concatenate([decode_curve(c) for c in entry["curves"]])


def decode_curve(encoded: dict) -> np.ndarray:
    """Decode one encoded PolylineCurve and return its vertices."""
    curve = rhino3dm.CommonObject.Decode(encoded)
    assert isinstance(curve, rhino3dm.PolylineCurve)
    return curve_vertices(curve)


@pytest.fixture
def options() -> ExportOptions:
    """Return options with a large site offset, in millimetres."""
    return ExportOptions(site=parse_site(SITE), evaluation_id="ev-42", title="Lab run")


@pytest.fixture
def document(two_estimates: EvaluationResult, options: ExportOptions) -> dict:
    """Return the exported JSON document, parsed."""
    return json.loads(rhino.export_3dm_json(two_estimates, options))


def test_document_metadata(document: dict):
    """The document names its format, units, evaluation, frame and deviation."""
    assert document["format"] == "loceval.paths.3dm.json"
    assert document["format_version"] == 2
    assert document["units"] == "mm"
    assert document["rhino_unit_system"] == "Millimeters"
    base = np.array(document["base_point"])
    assert np.abs(base - [512340000.0, 5403210000.0, 112000.0]).max() < 10_000.0
    meta = document["metadata"]
    assert meta["evaluation_id"] == "ev-42"
    assert meta["title"] == "Lab run"
    assert meta["frame"]["evaluation_frame"] == "map"
    assert meta["simplify_tolerance_m"] == 0.001
    assert 0.0 < meta["max_deviation_m"] <= 0.001


def test_paths_names_colours_layers(document: dict):
    """Per path: name, palette colour, layer path and the encoded curve's fields."""
    paths = document["paths"]
    assert [p["name"] for p in paths] == ["OptiTrack", "RTAB-Map", "ISAAC"]
    assert [p["color"] for p in paths] == [[0, 255, 255], [255, 0, 255], [0, 200, 0]]
    assert [p["layer"] for p in paths] == [
        "loceval::Lab run::OptiTrack",
        "loceval::Lab run::RTAB-Map",
        "loceval::Lab run::ISAAC",
    ]
    for path in paths:
        assert len(path["curves"]) == path["pieces"] == 1  # no tracking loss in this walk
        for curve in path["curves"] + [run["curve"] for run in path["ate"]]:
            assert set(curve) == {"version", "archive3dm", "opennurbs", "data"}
            assert curve["archive3dm"] <= 70  # decodable by Rhino 7
    assert [p["ate"] == [] for p in paths] == [True, False, False]
    bin_colours = [b["color"] for b in document["ate_bins"]]
    assert all(run["color"] in bin_colours for p in paths for run in p["ate"])
    assert all(p["ate_layer"] == p["layer"] + "::ATE" for p in paths)
    worst = [m for m in document["markers"] if m["kind"] == "worst"]
    assert {m["layer"] for m in worst} == {
        "loceval::Lab run::RTAB-Map::markers",
        "loceval::Lab run::ISAAC::markers",
    }


def test_every_curve_decodes_to_the_trajectory(
    document: dict, two_estimates: EvaluationResult, options: ExportOptions
):
    """CommonObject.Decode gives vertices within 1 mm of the mapped poses, all kept counted."""
    for entry, expected in zip(
        document["paths"], expected_paths(two_estimates, options), strict=True
    ):
        vertices = decode(entry)
        assert len(vertices) == entry["vertices"]
        assert entry["poses"] == len(expected)
        np.testing.assert_allclose(vertices[[0, -1]], expected[[0, -1]], rtol=0, atol=1e-6)
        assert polyline_distances(expected, vertices).max() <= 1.0 + 1e-6  # mm
        assert entry["max_deviation_m"] <= 0.001


def test_same_curves_as_the_3dm(
    document: dict, two_estimates: EvaluationResult, options: ExportOptions
):
    """The JSON curves are exactly the .3dm curves."""
    model = rhino3dm.File3dm.FromByteArray(rhino.export_3dm(two_estimates, options))
    curves = {
        o.Attributes.Name: o.Geometry
        for o in model.Objects
        if o.Geometry.ObjectType == rhino3dm.ObjectType.Curve
    }
    for entry in document["paths"]:
        curve = curves[entry["name"]]
        np.testing.assert_array_equal(decode(entry), curve_vertices(curve))


def test_pieces_at_a_tracking_loss(two_estimates: EvaluationResult):
    """A 3 s reference loss splits every path into two curves and gives one loss marker."""
    gapped = with_reference_loss(two_estimates)
    document = json.loads(rhino.export_3dm_json(gapped, ExportOptions(title="Gap run")))
    for entry in document["paths"]:
        first, second = (decode_curve(c) for c in entry["curves"])
        assert np.linalg.norm(second[0] - first[-1]) > 1000.0  # mm: 3 s of walking apart
    (loss,) = [m for m in document["markers"] if m["kind"] == "gap"]
    assert loss["layer"] == "loceval::Gap run::tracking loss"
    assert loss["label"].startswith("no pose for 3.0 s")


def test_units_scale(two_estimates: EvaluationResult):
    """Metre output is the millimetre output divided by 1000."""
    mm = json.loads(rhino.export_3dm_json(two_estimates, ExportOptions(units=Units.MM)))
    m = json.loads(rhino.export_3dm_json(two_estimates, ExportOptions(units=Units.M)))
    assert (mm["units"], m["units"]) == ("mm", "m")
    for a, b in zip(mm["paths"], m["paths"], strict=True):
        np.testing.assert_allclose(decode(a), 1000.0 * decode(b), rtol=1e-12)


def test_script_reads_only_fields_the_document_has(document: dict):
    """Every key the Grasshopper script looks up exists in the document it reads."""
    keys = grasshopper_script_keys()
    available = set(document) | set(document["metadata"]) | set(document["paths"][1])
    available |= set(document["markers"][0]) | set(document["paths"][1]["ate"][0])
    available |= set(document["ate_bins"][0])
    assert keys
    assert keys <= available, keys - available
    assert document["units"] in {"mm", "cm", "m"}  # the script's UNIT_SYSTEMS


def test_script_is_short_and_compiles():
    """The script is valid Python 3 and short enough to review by eye."""
    source = GRASSHOPPER_SCRIPT.read_text(encoding="utf-8")
    compile(source, str(GRASSHOPPER_SCRIPT), "exec")
    assert len(source.splitlines()) <= 140
    assert "CommonObject.FromJSON" in source


def test_script_uses_only_python_2_7_syntax():
    """Rhino 7's GhPython is IronPython 2.7: no f-strings, annotations, pathlib or walrus."""
    source = GRASSHOPPER_SCRIPT.read_text(encoding="utf-8")
    tree = ast.parse(source)
    python3_only = (ast.JoinedStr, ast.AnnAssign, ast.NamedExpr, ast.Nonlocal, ast.YieldFrom)
    assert not [type(n).__name__ for n in ast.walk(tree) if isinstance(n, python3_only)]
    functions = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)]
    assert functions
    for function in functions:
        assert function.returns is None
        assert function.args.kwonlyargs == []
        assert all(a.annotation is None for a in function.args.args)
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert imported <= {"io", "json", "Rhino", "System.Drawing", "urllib.request", "urllib2"}
    assert "io.open(" in source  # the builtin open of Python 2 has no encoding argument
