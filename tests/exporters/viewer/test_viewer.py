"""The viewer's data and HTML: pinned three.js, display set, site frame, one closed file."""

from __future__ import annotations

import base64
import csv
import hashlib
import io
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from exporters import ARTIFACTS, artifact_name, write_artifacts
from exporters.cad.placement import place_evaluation
from exporters.cad.points_placement import place_control_points
from exporters.cad.site import parse_site
from exporters.checkpoints import checkpoint_errors_csv, write_checkpoint_artifacts
from exporters.colours import error_bins, hex_colour
from exporters.errors import ExportError
from exporters.options import ExportOptions, Units
from exporters.tables import export_errors_csv
from exporters.viewer import display_indices, export_viewer_html, viewer_scene
from exporters.viewer.checkpoints import checkpoint_scene
from exporters.viewer.page import DEFAULT_TEMPLATES_DIR
from exporters.viewer.vendor import THREE_FILE, THREE_SHA256, THREE_VERSION, three_script
from loceval.checkpoint_evaluation import (
    CheckpointConfig,
    CheckpointEvaluation,
    evaluate_control_points,
)
from loceval.core.gaps import path_breaks
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from loceval.radio_evaluation import RangingConfig, evaluate_radio
from loceval.registration.alignment import AlignMethod
from loceval.trajectory import Trajectory
from tests.checkpoint_factory import grid_points, stop_and_go
from tests.exporters.conftest import with_reference_loss
from tests.radio_factory import make_ranges, make_reference

NS = 1_000_000_000
THREE = DEFAULT_TEMPLATES_DIR / THREE_FILE
SCENE = re.compile(r'<script type="application/json" id="[^"]*-scene">(.*?)</script>', re.DOTALL)
SCRIPTS = re.compile(r"<script>(.*?)</script>", re.DOTALL)


def scene_of(html: bytes) -> dict:
    """Return the scene JSON a viewer page carries."""
    found = SCENE.search(html.decode("utf-8"))
    assert found is not None
    return json.loads(found.group(1))


def errors_rows(result: EvaluationResult) -> list[dict[str, str]]:
    """Return errors.csv as dictionaries."""
    text = export_errors_csv(result, ExportOptions()).decode("utf-8")
    return list(csv.DictReader(io.StringIO(text)))


# --- the vendored library ---------------------------------------------------------------


def test_vendored_three_matches_the_pin() -> None:
    """The vendored three.js is the pinned npm build, with its MIT licence beside it."""
    assert hashlib.sha256(THREE.read_bytes()).hexdigest() == THREE_SHA256
    assert THREE.read_text(encoding="utf-8").startswith("/**\n * @license")
    assert f'const t="{THREE_VERSION.split(".")[1]}"' in THREE.read_text(encoding="utf-8")[:400]
    licence = (THREE.parent / "LICENSE").read_text(encoding="utf-8")
    assert "The MIT License" in licence
    assert "three.js authors" in licence
    readme = (THREE.parent / "README.md").read_text(encoding="utf-8")
    assert THREE_VERSION in readme
    assert THREE_SHA256 in readme
    assert "make vendor-three" in readme


def test_three_becomes_a_classic_script() -> None:
    """The module's export clause becomes globalThis.LOCEVAL_THREE; nothing else changes."""
    script = three_script(DEFAULT_TEMPLATES_DIR)
    assert "export{" not in script[-20000:]
    assert "WebGLRenderer:" in script
    assert script.count("globalThis.LOCEVAL_THREE=") == 1
    body = THREE.read_text(encoding="utf-8")
    assert body[: body.rindex("export{")] in script


def test_damaged_three_is_refused(tmp_path: Path) -> None:
    """A vendored file that differs from the pin is refused, naming the fix."""
    (tmp_path / THREE_FILE).parent.mkdir(parents=True)
    (tmp_path / THREE_FILE).write_bytes(THREE.read_bytes().replace(b"170", b"171", 1))
    with pytest.raises(ExportError, match="make vendor-three"):
        three_script(tmp_path)
    with pytest.raises(ExportError, match="cannot be read"):
        three_script(tmp_path / "missing")


# --- the display set ----------------------------------------------------------------------


def test_short_paths_are_kept_whole() -> None:
    """A path within the budget is drawn pose for pose."""
    xyz = np.zeros((500, 3))
    kept = display_indices(xyz, np.zeros(499, dtype=bool), budget=500)
    np.testing.assert_array_equal(kept, np.arange(500))


def test_long_path_keeps_peaks_breaks_and_shape(rng: np.random.Generator) -> None:
    """1,000,000 poses: about the budget kept, every bucket's error peak, both ends of breaks."""
    n = 1_000_000
    t = np.linspace(0.0, 200.0, n)
    xyz = np.stack([np.cos(t / 10) * 20, np.sin(t / 7) * 15, 0.01 * t], axis=1)
    errors = np.abs(rng.normal(0.0, 0.02, n))
    spikes = rng.choice(n, 40, replace=False)
    errors[spikes] = 1.0 + np.arange(40) / 100.0
    breaks = np.zeros(n - 1, dtype=bool)
    cut = rng.choice(n - 1, 25, replace=False)
    breaks[cut] = True
    start = time.perf_counter()
    kept = display_indices(xyz, breaks, errors_m=errors, must_keep=np.array([7, 11]))
    took = time.perf_counter() - start
    assert took < 2.0  # vectorised (about 0.1 s); a loop over poses would take far longer
    assert 2_000 <= len(kept) <= 21_000  # 2,000 buckets of 500 poses, up to 10 kept in each
    assert np.all(np.diff(kept) > 0)
    assert set(spikes.tolist()) <= set(kept.tolist())
    assert set(cut.tolist()) | set((cut + 1).tolist()) <= set(kept.tolist())
    assert {0, n - 1, 7, 11} <= set(kept.tolist())
    # the outline: every extreme coordinate of the path is a kept pose
    for axis in range(3):
        assert int(np.argmin(xyz[:, axis])) in kept
        assert int(np.argmax(xyz[:, axis])) in kept


# --- the scene ----------------------------------------------------------------------------


def test_scene_is_in_the_cad_frame_and_units(two_estimates: EvaluationResult) -> None:
    """Vertices are the CAD files' model coordinates (site, units) minus the same base point."""
    options = ExportOptions(units=Units.MM, site=parse_site("100 200 5 30"), simplify_m=0.0)
    scene = viewer_scene(two_estimates, options)
    placement = place_evaluation(two_estimates, options)
    assert scene["units"] == "mm"
    np.testing.assert_allclose(scene["base"], placement.base_point)
    assert [p["name"] for p in scene["paths"]] == [p.name for p in placement.paths]
    for shown, placed in zip(scene["paths"], placement.paths, strict=True):
        xyz = np.array(shown["xyz"]).reshape(-1, 3)
        assert len(xyz) == shown["poses"] == len(placed.stamps_ns)
        # vertices are rounded to 0.1 mm
        np.testing.assert_allclose(xyz + scene["base"], placed.vertices, atol=0.0501)
        assert shown["color"] == placed.color_hex
    ref = scene["paths"][0]
    assert ref["t"][0] == 0.0
    assert ref["kind"] == "reference"


def test_scene_errors_are_errors_csv(two_estimates: EvaluationResult) -> None:
    """Each estimate vertex carries the stamp and ATE of its errors.csv row."""
    scene = viewer_scene(two_estimates, ExportOptions())
    rows = errors_rows(two_estimates)
    for path in scene["paths"][1:]:
        mine = [r for r in rows if r["estimate"] == path["name"]]
        assert len(mine) == len(path["t"]) == len(path["err"])
        np.testing.assert_allclose(path["t"], [float(r["t_s"]) for r in mine], atol=1e-6)
        assert path["err"] == [float(r["ate_m"]) for r in mine]
        ref_m = np.array([[float(r[f"ref_{a}"]) for a in "xyz"] for r in mine])
        shown = np.array(path["ref"]).reshape(-1, 3) + scene["base"]
        np.testing.assert_allclose(shown, ref_m * scene["per_metre"], atol=0.0501)  # 0.1 mm


def test_scene_breaks_at_tracking_loss(two_estimates: EvaluationResult) -> None:
    """A reference loss of 3 s breaks the reference and every estimate, as path_breaks says."""
    result = with_reference_loss(two_estimates)
    scene = viewer_scene(result, ExportOptions())
    losses = result.reference.tracking_losses(NS // 10)
    assert len(losses) == 1
    ref = scene["paths"][0]
    expected = np.flatnonzero(path_breaks(result.reference.stamps_ns, min_gap_ns=NS // 10))
    assert ref["breaks"] == expected.tolist()
    for path in scene["paths"][1:]:
        assert len(path["breaks"]) == 1
        k = path["breaks"][0]
        assert path["t"][k] < 20.0 + 1e-9
        assert path["t"][k + 1] > 23.0


def test_scene_worst_labels_and_bins(two_estimates: EvaluationResult) -> None:
    """Greatest errors are labelled at their vertex; the bins are the report's colour scale."""
    scene = viewer_scene(two_estimates, ExportOptions())
    assert scene["worst"]
    for label in scene["worst"]:
        path = scene["paths"][label["path"]]
        error = path["err"][label["index"]]
        assert f"{error:.3f} m" in label["label"]
        assert label["label"].startswith(path["name"])
    bins = scene["bins"]
    # the evaluation's tolerance (0.10 m) anchors the scale: green within, orange to red beyond
    expected = error_bins(two_estimates)
    assert [b["color"] for b in bins] == [hex_colour(b.color_rgb) for b in expected]
    assert [b["beyond"] for b in bins] == [False, False, True, True, True]
    assert bins[-1]["high"] is None
    assert [b["high"] for b in bins[:-1]] == sorted(b["high"] for b in bins[:-1])


def test_building_mesh_and_plan(tmp_path: Path, two_estimates: EvaluationResult) -> None:
    """An OBJ building is a mesh and a DXF a plan, both relative to the paths' base point."""
    trimesh = pytest.importorskip("trimesh")
    ezdxf = pytest.importorskip("ezdxf")
    box = trimesh.creation.box(extents=(12.0, 10.0, 3.0))
    box.apply_translation([0.0, 0.0, 1.5])
    obj = tmp_path / "box.obj"
    box.export(obj)
    scene = viewer_scene(two_estimates, ExportOptions(building=obj, units=Units.M))
    mesh = scene["building"]
    assert mesh["kind"] == "mesh"
    positions = np.array(mesh["positions"]).reshape(-1, 3) + scene["base"]
    np.testing.assert_allclose(positions.min(axis=0), [-6.0, -5.0, 0.0], atol=1e-4)
    assert len(mesh["index"]) == 3 * len(box.faces)
    doc = ezdxf.new("R2013", units=ezdxf.units.M)
    doc.modelspace().add_line((0, 0), (5, 0))
    dxf = tmp_path / "plan.dxf"
    doc.saveas(dxf)
    plan = viewer_scene(two_estimates, ExportOptions(building=dxf, units=Units.M))["building"]
    assert plan["kind"] == "plan"
    ends = np.array(plan["segments"]).reshape(-1, 3)[:, :2] + scene["base"][:2]
    np.testing.assert_allclose(ends, [[0, 0], [5, 0]], atol=1e-4)


def test_no_building_means_no_mesh(two_estimates: EvaluationResult) -> None:
    """Without a building model the viewer draws a grid (no building in the scene)."""
    assert viewer_scene(two_estimates, ExportOptions())["building"] is None


# --- the page -----------------------------------------------------------------------------


def test_viewer_html_is_closed_and_self_contained(two_estimates: EvaluationResult) -> None:
    """One file: CSP default-src 'none' with the hashes of exactly its two inline scripts."""
    html = export_viewer_html(two_estimates, ExportOptions(title="Site <b>A</b>")).decode("utf-8")
    csp = re.search(r'http-equiv="Content-Security-Policy" content="([^"]*)"', html)
    assert csp is not None
    assert csp.group(1).startswith("default-src 'none'; script-src 'sha256-")
    scripts = SCRIPTS.findall(html)
    assert len(scripts) == 2
    for script in scripts:
        digest = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
        assert f"'sha256-{digest}'" in csp.group(1)
    assert re.search(r"\s(src|href)=", html) is None  # nothing to load
    assert "Site &lt;b&gt;A&lt;/b&gt;" in html
    assert 'data-ready="false"' in html


def test_hostile_names_stay_text(two_estimates: EvaluationResult) -> None:
    """A name holding </script> cannot end the scene's element; it reads back unchanged."""
    est = two_estimates.estimates[0].estimate
    hostile = Trajectory(
        est.stamps_ns, est.positions_xyz, est.quat_xyzw, name="x</script><script>alert(1)//"
    )
    result = evaluate(two_estimates.reference, [hostile], two_estimates.config)
    html = export_viewer_html(result, ExportOptions())
    assert html.count(b"</script>") == 3
    assert scene_of(html)["paths"][1]["name"] == "x</script><script>alert(1)//"


def test_viewer_is_an_artifact(tmp_path: Path, two_estimates: EvaluationResult) -> None:
    """viewer.html is in the registry (alias 'viewer') and written like every artifact."""
    assert ARTIFACTS["viewer.html"].media_type == "text/html"
    assert artifact_name("viewer") == "viewer.html"
    written = write_artifacts(
        two_estimates, tmp_path / "out", ExportOptions(), names=["viewer.html"]
    )
    assert [p.name for p in written] == ["viewer.html"]
    assert scene_of(written[0].read_bytes())["paths"][0]["name"] == "OptiTrack"


# --- control points ---------------------------------------------------------------------------


@pytest.fixture
def survey(rng: np.random.Generator) -> CheckpointEvaluation:
    """A 3 x 4 grid at 30 cm visited twice; the 4 corners' visits fix the alignment."""
    rec = stop_and_go(rng, grid_points(3, 4), passes=2)
    return evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(align_points=("P00", "P03", "P20", "P23")),
        reference_name="survey",
    )


def test_checkpoint_scene_is_the_cad_placement(survey: CheckpointEvaluation) -> None:
    """Control points and visits sit where the CAD files put them, with errors.csv's errors."""
    options = ExportOptions(units=Units.MM, site=parse_site("100 200 5 30"))
    scene = checkpoint_scene(survey, options)
    placed = place_control_points(survey, options)
    np.testing.assert_allclose(scene["base"], placed.base_point)
    shown = np.array([p["xyz"] for p in scene["controls"]["points"]]) + scene["base"]
    np.testing.assert_allclose(shown, placed.points, atol=0.0501)  # 0.1 mm
    rows = list(csv.DictReader(io.StringIO(checkpoint_errors_csv(survey).decode())))
    visits = scene["controls"]["visits"]
    assert len(visits) == len(rows) == 24
    for visit, row, measured in zip(visits, rows, placed.estimates[0].measured, strict=True):
        assert visit["id"] == row["id"]
        assert visit["error"] == float(row["error_m"])
        assert visit["alignment"] == (row["used_for_alignment"] == "true")
        assert (visit["color"] == "#808080") == visit["alignment"]
        np.testing.assert_allclose(
            np.array(visit["measured"]) + scene["base"], measured, atol=0.0501
        )
    (track,) = scene["paths"]
    assert track["kind"] == "track"
    assert scene["mode"] == "checkpoints"


def test_checkpoint_viewer_is_an_artifact(survey: CheckpointEvaluation, tmp_path: Path) -> None:
    """write_checkpoint_artifacts writes viewer.html with the control points in it."""
    written = write_checkpoint_artifacts(
        survey, tmp_path / "out", ExportOptions(), names=["viewer.html"]
    )
    scene = scene_of(written[0].read_bytes())
    assert [p["id"] for p in scene["controls"]["points"]] == list(survey.points.ids)


def test_uncertainty_ellipses_follow_the_covariance(two_estimates: EvaluationResult) -> None:
    """A reported covariance gives 2-sigma ellipses: semi-axes 2 sqrt(eigenvalues), in units."""
    truth = two_estimates.reference
    est = two_estimates.estimates[0].estimate
    cov = np.zeros((len(est), 6, 6))
    cov[:, 0, 0] = 0.03**2  # sigma 3 cm along the estimate's x, 1 cm along y
    cov[:, 1, 1] = 0.01**2
    cov[:, 2, 2] = 0.01**2
    with_cov = Trajectory(est.stamps_ns, est.positions_xyz, name="AMCL-like", cov6=cov)
    result = evaluate(truth, [with_cov], two_estimates.config)
    scene = viewer_scene(result, ExportOptions(units=Units.CM, site=parse_site("0 0 0 90")))
    shown = scene["paths"][1]["uncertainty"]
    assert 0 < len(shown["index"]) <= 400
    ellipse = np.array(shown["ellipse"]).reshape(-1, 3)
    np.testing.assert_allclose(ellipse[:, 0], 6.0, rtol=1e-3)  # 2 sigma of 3 cm, in cm
    np.testing.assert_allclose(ellipse[:, 1], 2.0, rtol=1e-3)
    # the alignment turned the estimate's x axis; the site turns it by another 90 degrees
    turn = result.estimates[0].alignment.transform.rotation
    expected = np.arctan2(turn[1, 0], turn[0, 0]) + np.pi / 2
    assert np.allclose(
        np.cos(2 * (ellipse[:, 2] - expected)), 1.0, atol=1e-3
    )  # an axis, not a direction
    assert viewer_scene(two_estimates, ExportOptions())["paths"][1]["uncertainty"] is None


def test_radio_anchors_are_placed(rng: np.random.Generator) -> None:
    """A ranging evaluation's anchors are drawn where the site puts them, with their ids."""
    result = evaluate_radio(make_reference(), make_ranges(rng, end_s=20.0).ranges, RangingConfig())
    options = ExportOptions(units=Units.M, site=parse_site("10 20 0 90"))
    scene = viewer_scene(result, options)
    anchors = result.ranging.anchors if result.ranging is not None else ()
    assert [a["id"] for a in scene["anchors"]] == [a.id for a in anchors]
    shown = np.array([a["xyz"] for a in scene["anchors"]]) + scene["base"]
    expected = options.site.apply_positions(np.array([a.position_xyz for a in anchors]))
    np.testing.assert_allclose(shown, expected, atol=1e-4)
