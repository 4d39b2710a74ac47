"""The .3dm, 3DM-JSON and GLB of an evaluation against control points, read back.

Every file is compared with ``paths.dxf`` (read with ezdxf), the reference for the content:
the same points, measured positions, error lines and labels on the same layers, within
1 mm, in mm at a far site (512 km east), so float32 or a lost offset would show.
"""

from __future__ import annotations

import json
from pathlib import Path

import ezdxf
import numpy as np
import pytest

from exporters.cad.site import parse_site
from exporters.checkpoints import write_checkpoint_artifacts
from exporters.options import ExportOptions, Units
from loceval.checkpoint_evaluation import (
    CheckpointConfig,
    CheckpointEvaluation,
    evaluate_control_points,
)
from loceval.evaluation import EvaluationConfig
from loceval.registration.alignment import AlignMethod
from tests.checkpoint_factory import grid_points, stop_and_go
from tests.exporters.conftest import GRASSHOPPER_SCRIPT, Validator, grasshopper_script_keys

rhino3dm = pytest.importorskip("rhino3dm")
pygltflib = pytest.importorskip("pygltflib")

FAR_SITE = "512340.25 5403210.5 112.3 37.5"
ROOT = "loceval::survey vs est"
R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # Z up -> Y up
TOL_MM = 1.0


@pytest.fixture
def evaluation(rng: np.random.Generator) -> CheckpointEvaluation:
    """A 3 x 4 grid at 30 cm visited twice; the 4 corners' 8 visits are alignment (grey)."""
    rec = stop_and_go(rng, grid_points(3, 4), passes=2)
    return evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(align_points=("P00", "P03", "P20", "P23")),
        reference_name="survey",
    )


@pytest.fixture
def out(evaluation: CheckpointEvaluation, tmp_path: Path) -> Path:
    """Every artifact in mm at the far site."""
    options = ExportOptions(
        units=Units.MM, site=parse_site(FAR_SITE), evaluation_id="ev1", title="survey vs est"
    )
    write_checkpoint_artifacts(evaluation, tmp_path / "out", options)
    return tmp_path / "out"


def dxf_content(path: Path) -> dict[str, np.ndarray]:
    """Return the DXF's points per layer and the error lines as (N, 6) start + end, mm."""
    msp = ezdxf.readfile(path).modelspace()
    layers = {e.dxf.layer for e in msp}
    out = {
        layer: np.array([tuple(p.dxf.location) for p in msp.query(f'POINT[layer=="{layer}"]')])
        for layer in layers
    }
    lines = msp.query('LINE[layer=="est errors"]')
    out["lines"] = np.array([(*l.dxf.start, *l.dxf.end) for l in lines])  # noqa: E741
    return out


def dxf_labels(path: Path, layer: str) -> list[str]:
    """Return the texts on a DXF layer, in drawing order."""
    msp = ezdxf.readfile(path).modelspace()
    return [t.dxf.text for t in msp.query(f'TEXT[layer=="{layer}"]')]


def p3(point: rhino3dm.Point3d) -> list[float]:
    """Return a Point3d's coordinates."""
    return [point.X, point.Y, point.Z]


def test_alignment_visits_exist(evaluation: CheckpointEvaluation) -> None:
    """The fixture has grey (alignment) and scored visits, so both colours are tested."""
    flags = [v.used_for_alignment for v in evaluation.estimates[0].result.visits]
    assert (len(flags), sum(flags)) == (24, 8)  # 12 points x 2 passes; 4 corners x 2


@pytest.mark.pdf
def test_3dm_matches_the_dxf(out: Path) -> None:
    """.3dm: point objects, text dots and lines on the DXF's layers at its coordinates."""
    dxf = dxf_content(out / "paths.dxf")
    model = rhino3dm.File3dm.Read(str(out / "paths.3dm"))
    assert model.Settings.ModelUnitSystem == rhino3dm.UnitSystem.Millimeters
    layers = [layer.FullPath for layer in model.Layers]
    assert layers == [
        "loceval",
        ROOT,
        f"{ROOT}::control points",
        f"{ROOT}::est measured",
        f"{ROOT}::est errors",
    ]
    by_layer: dict[str, dict[str, list]] = {name: {} for name in layers}
    for obj in model.Objects:  # a few dozen objects
        kind = type(obj.Geometry).__name__
        by_layer[layers[obj.Attributes.LayerIndex]].setdefault(kind, []).append(obj)

    def xyz(objs: list) -> np.ndarray:  # a Point's Location, a TextDot's Point
        return np.array([p3(getattr(o.Geometry, "Location", None) or o.Geometry.Point)
                         for o in objs])  # fmt: skip

    points = by_layer[f"{ROOT}::control points"]
    np.testing.assert_allclose(xyz(points["Point"]), dxf["control points"], atol=TOL_MM)
    np.testing.assert_allclose(xyz(points["TextDot"]), dxf["control points"], atol=TOL_MM)
    ids = [o.Geometry.Text for o in points["TextDot"]]
    assert ids == dxf_labels(out / "paths.dxf", "control points")
    measured = by_layer[f"{ROOT}::est measured"]["Point"]
    np.testing.assert_allclose(xyz(measured), dxf["est measured"], atol=TOL_MM)
    errors = by_layer[f"{ROOT}::est errors"]
    lines = np.array([
        [*p3(o.Geometry.PointAtStart), *p3(o.Geometry.PointAtEnd)] for o in errors["LineCurve"]
    ])  # fmt: skip
    np.testing.assert_allclose(lines, dxf["lines"], atol=TOL_MM)
    assert [o.Geometry.Text for o in errors["TextDot"]] == dxf_labels(
        out / "paths.dxf", "est errors"
    )
    grey = [o.Attributes.ObjectColor[:3] for o in errors["LineCurve"]]
    assert sorted(set(grey)) == [(128, 128, 128), (212, 0, 154)]  # alignment, estimate 0
    assert model.Strings["loceval.evaluation_id"] == "ev1"


@pytest.mark.pdf
def test_json_matches_the_dxf(out: Path) -> None:
    """paths.3dm.json: encoded lines, points and dots carry the DXF's coordinates."""
    dxf = dxf_content(out / "paths.dxf")
    doc = json.loads((out / "paths.3dm.json").read_text())
    assert (doc["format"], doc["format_version"], doc["units"]) == (
        "loceval.paths.3dm.json", 2, "mm"
    )  # fmt: skip
    (path,) = doc["paths"]
    assert path["layer"] == f"{ROOT}::est errors"
    curves = [rhino3dm.CommonObject.Decode(c) for c in path["curves"]]
    assert {type(c).__name__ for c in curves} == {"PolylineCurve"}  # as a trajectory's
    assert {c.PointCount for c in curves} == {2}
    assert path["poses"] == len(curves) == 24  # 12 points, 2 passes
    hops = {"name", "kind", "source", "poses", "vertices", "max_deviation_m", "color"}
    assert hops <= set(path)  # what service/api/hops.py reads of a path
    lines = np.array([[*p3(c.PointAtStart), *p3(c.PointAtEnd)] for c in curves])
    np.testing.assert_allclose(lines, dxf["lines"], atol=TOL_MM)
    for layer in ("control points", "est measured"):
        got = [p["position"] for p in doc["points"] if p["layer"] == f"{ROOT}::{layer}"]
        np.testing.assert_allclose(got, dxf[layer], atol=TOL_MM)
    labels = [m["label"] for m in doc["markers"] if m["layer"] == f"{ROOT}::est errors"]
    assert labels == dxf_labels(out / "paths.dxf", "est errors")
    np.testing.assert_allclose(doc["base_point"], [512340000.0, 5403211000.0, 112000.0])


@pytest.mark.pdf
def test_grasshopper_script_reads_the_control_points_document(out: Path) -> None:
    """Every key the Grasshopper script subscripts exists in the control-point document."""
    doc = json.loads((out / "paths.3dm.json").read_text())
    keys = grasshopper_script_keys()
    available = set(doc) | set(doc["metadata"]) | set(doc["paths"][0]) | set(doc["markers"][0])
    available |= set(doc["points"][0])
    assert keys - {"bin", "curve"} <= available, keys - available  # ATE runs: none here
    assert 'document.get("points", [])' in GRASSHOPPER_SCRIPT.read_text(encoding="utf-8")


def glb_world(model: pygltflib.GLTF2, node: pygltflib.Node, primitive: int = 0) -> np.ndarray:
    """Return a root node's primitive POSITIONs in Z-up model millimetres (float64)."""
    acc = model.accessors[model.meshes[node.mesh].primitives[primitive].attributes.POSITION]
    view = model.bufferViews[acc.bufferView]
    local = np.frombuffer(model.binary_blob(), np.float32, acc.count * 3, view.byteOffset)
    matrix = np.array(node.matrix, dtype=np.float64).reshape(4, 4).T
    y_up = local.reshape(-1, 3).astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
    out: np.ndarray = y_up @ R * 1000.0  # R is a rotation: R.T undoes it, (R.T @ v).T = v @ R
    return out


@pytest.mark.pdf
def test_glb_matches_the_dxf(out: Path, validate: Validator) -> None:
    """GLB: POINTS and LINES nodes per layer, Y up in metres, the DXF's points within 1 mm."""
    data = (out / "paths.glb").read_bytes()
    dxf = dxf_content(out / "paths.dxf")
    model = pygltflib.GLTF2.load_from_bytes(data)
    roots = {model.nodes[k].name: model.nodes[k] for k in model.scenes[0].nodes}
    assert list(roots) == ["control points", "est measured", "est errors"]
    points = roots["control points"]
    assert model.meshes[points.mesh].primitives[0].mode == pygltflib.POINTS
    np.testing.assert_allclose(glb_world(model, points), dxf["control points"], atol=TOL_MM)
    ids = [model.nodes[k].name for k in points.children]
    assert ids == dxf_labels(out / "paths.dxf", "control points")
    np.testing.assert_allclose(
        glb_world(model, roots["est measured"]), dxf["est measured"], atol=TOL_MM
    )
    errors = roots["est errors"]
    scored, alignment = model.meshes[errors.mesh].primitives
    assert scored.mode == alignment.mode == pygltflib.LINES
    pairs = np.concatenate([glb_world(model, errors, 0), glb_world(model, errors, 1)])
    visits = pairs.reshape(-1, 6)
    grey = np.array(["(alignment)" in t for t in dxf_labels(out / "paths.dxf", "est errors")])
    expected = np.concatenate([dxf["lines"][~grey], dxf["lines"][grey]])
    np.testing.assert_allclose(visits, expected, atol=TOL_MM)
    labels = [model.nodes[k].name for k in errors.children]
    assert labels == dxf_labels(out / "paths.dxf", "est errors")
    report = validate(data)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
