"""The verdict on the building, in headless Chromium: where a system is out of tolerance, to scale.

A generated two-room office (:mod:`tests.exporters.office`) as IFC with named spaces, as a
DXF plan with labelled rooms and as a Z-up GLB written by trimesh; a run whose error exceeds
0.025 m in two known stretches, both in ``2.14 Office``. One browser, four page loads:

- IFC: the root's contract (``data-tolerance-m``, ``data-verdicts``, ``data-beyond``) equals
  what ``errors.csv`` gives (stretches recomputed from its rows, rooms from the plan's
  numbers); the tolerance's colours are drawn at the stretches' projected vertices and
  nowhere else; the scale bar's pixels per metre match the projected geometry; the outer
  walls are in the first frame; a click on a stretch moves the timeline and the view
  there; labels neither overlap nor leave the frame, at 1200 and at 420 px wide.
- DXF: the same stretches and rooms from the plan's labels; the scale bar matches the drawn
  wall lines measured in the canvas's pixels (within 2 %).
- GLB as written (Z-up data in a Y-up format): a warning names the setting; with it set, the
  model stands upright (3 m tall) and no warning is left.

Screenshots go to ``$LOCEVAL_SCREENSHOTS`` when set (else the test's tmp_path).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exporters.options import ExportOptions, Units, UpAxis
from exporters.tables import export_errors_csv
from exporters.viewer import export_viewer_html
from loceval.evaluation import EvaluationResult
from tests.exporters.ifcfactory import OFFICE_HEIGHT_M, OFFICE_WALLS, wall_corners
from tests.exporters.office import (
    TOLERANCE_M,
    evaluate_office,
    room_of,
    write_office,
    write_office_glb,
    write_office_plan,
)
from tests.exporters.viewer.test_viewer_browser import ROOT, browser, hex_rgb, open_viewer

__all__ = ["browser"]  # the module-scoped fixture: one browser for this module

pytestmark = [pytest.mark.slow]

OUTER_MIN = np.array([-0.2, -0.2])
OUTER_MAX = np.array([10.2, 6.2])
"""The outer faces of the office's walls, model metres."""


@pytest.fixture(scope="module")
def run() -> EvaluationResult:
    """The office run, no alignment (the ATE is the known error), tolerance 0.025 m @ 95 %."""
    return evaluate_office()


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The office as IFC, DXF and GLB."""
    pytest.importorskip("ifcopenshell")
    out = tmp_path_factory.mktemp("office")
    write_office(out / "office.ifc")
    write_office_plan(out / "office.dxf")
    write_office_glb(out / "office.glb")
    return out


def expected_stretches(result: EvaluationResult) -> list[dict[str, object]]:
    """The stretches beyond the tolerance recomputed from errors.csv's rows, worst first.

    Runs of consecutive rows with ``ate_m`` above the tolerance (the recording has no
    tracking loss); each in the room holding most of its ground-truth rows, by the
    office's room rectangles (not the building file).
    """
    text = export_errors_csv(result, ExportOptions()).decode("utf-8")
    rows = list(csv.DictReader(io.StringIO(text)))
    runs: list[list[dict[str, str]]] = []
    for prev, row in zip([None, *rows], rows, strict=False):
        if float(row["ate_m"]) <= TOLERANCE_M:
            continue
        if prev is None or float(prev["ate_m"]) <= TOLERANCE_M:
            runs.append([])
        runs[-1].append(row)
    out = []
    for run in sorted(runs, key=lambda r: -max(float(x["ate_m"]) for x in r)):
        rooms = [room_of(float(x["ref_x"]), float(x["ref_y"])) for x in run]
        out.append(
            {
                "estimate": run[0]["estimate"],
                "t0_s": float(run[0]["t_s"]),
                "t1_s": float(run[-1]["t_s"]),
                "space": max(set(rooms), key=rooms.count),
            }
        )
    return out


def settle(viewer: Any) -> None:
    """Wait for the next drawn frame (the viewer draws on animation frames)."""
    viewer.page.evaluate(
        "new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => r())))"
    )


def check_contract(viewer: Any, result: EvaluationResult) -> list[dict[str, object]]:
    """The root's tolerance, verdicts and stretches are the evaluation's, from errors.csv."""
    root = viewer.page.locator(ROOT)
    assert float(root.get_attribute("data-tolerance-m")) == TOLERANCE_M
    verdict = result.estimates[0].verdict
    assert verdict is not None
    assert json.loads(root.get_attribute("data-verdicts")) == {"slam": verdict.result}
    beyond = json.loads(root.get_attribute("data-beyond"))
    expected = expected_stretches(result)
    assert len(beyond) == len(expected) == 2
    for got, want in zip(beyond, expected, strict=True):
        assert got["estimate"] == want["estimate"]
        assert got["t0_s"] == pytest.approx(want["t0_s"], abs=1e-6)
        assert got["t1_s"] == pytest.approx(want["t1_s"], abs=1e-6)
        assert got["space"] == want["space"] == "2.14 Office"
    listed = viewer.page.locator(f"{ROOT} .lv-beyond li")
    assert listed.count() == 2
    assert "beyond 0.025 m for" in listed.first.inner_text()
    assert "in 2.14 Office" in listed.first.inner_text()
    head = viewer.page.locator(f"{ROOT} .lv-head").inner_text()
    assert verdict.result.upper() in head
    assert "within 0.025 m for 95 % of poses" in head
    return beyond


def check_beyond_colours(viewer: Any) -> None:
    """The colours beyond the tolerance are drawn at the stretches' vertices and nowhere else.

    The estimate alone is drawn; every canvas pixel in a beyond colour lies within 4 px of a
    projected vertex of a stretch, and most such vertices show a beyond colour.
    """
    from scipy.spatial import KDTree

    scene = viewer.scene
    viewer.api("showPath(0, false)")
    viewer.api("setTimeIndex(0)")
    pixels = viewer.canvas_pixels().astype(int)
    beyond_rgb = np.array([hex_rgb(b["color"]) for b in scene["bins"] if b.get("beyond")])
    within_rgb = np.array([hex_rgb(b["color"]) for b in scene["bins"] if not b.get("beyond")])
    assert len(beyond_rgb) == 3
    assert len(within_rgb) == 2
    near = np.abs(pixels[:, :, None, :] - beyond_rgb[None, None]).max(axis=3) <= 3
    ys, xs = np.nonzero(near.any(axis=2))
    assert len(xs) > 30  # the two stretches are drawn
    path = scene["paths"][1]
    points = np.array(viewer.api("project(1)"))
    in_stretch = np.zeros(len(points), dtype=bool)
    for b in scene["beyond"]:
        in_stretch[b["i0"] : b["i1"] + 1] = True
    errors = np.array(path["err"])
    np.testing.assert_array_equal(in_stretch, errors > TOLERANCE_M)
    distance, _ = KDTree(points[in_stretch]).query(np.column_stack([xs, ys]) + 0.5)
    assert distance.max() <= 4.0, distance.max()
    # and at the stretches' vertices the pixel is a beyond colour (a neighbour may cover it)
    h, w, _ = pixels.shape
    xy = np.floor(points[in_stretch]).astype(int)
    inside = (xy[:, 0] >= 0) & (xy[:, 0] < w) & (xy[:, 1] >= 0) & (xy[:, 1] < h)
    hits = near.any(axis=2)[xy[inside, 1], xy[inside, 0]]
    assert hits.mean() > 0.9
    viewer.api("showPath(0, true)")


def check_scale_bar(viewer: Any, a: list[float], b: list[float]) -> float:
    """The scale bar's pixels per metre equal the projection's between two local points."""
    settle(viewer)
    scale = viewer.page.locator(f"{ROOT} .lv-scale")
    assert scale.is_visible()
    metres = float(scale.get_attribute("data-scale-m"))
    px = float(scale.get_attribute("data-scale-px"))
    drawn = viewer.page.locator(f"{ROOT} .lv-scale-line").bounding_box()
    assert drawn["width"] == pytest.approx(px + 4, abs=1.5)  # the bar plus its two 2 px ends
    pa, pb = viewer.api(f"projectXYZ({json.dumps([*a, *b])})")
    per_metre = viewer.scene["per_metre"]
    distance_m = float(np.linalg.norm(np.subtract(a, b))) / per_metre
    projected = float(np.hypot(pa[0] - pb[0], pa[1] - pb[1])) / distance_m
    assert px / metres == pytest.approx(projected, rel=0.02)
    return px / metres


def outer_corners_local(scene: dict) -> list[float]:
    """The outer wall corners of the office in the scene's local coordinates (flat x, y, z)."""
    base, per_metre = scene["base"], scene["per_metre"]
    z = scene["paths"][0]["xyz"][2]
    out: list[float] = []
    for x, y in [OUTER_MIN, (OUTER_MAX[0], OUTER_MIN[1]), OUTER_MAX, (OUTER_MIN[0], OUTER_MAX[1])]:
        out += [x * per_metre - base[0], y * per_metre - base[1], z]
    return out


def check_walls_framed(viewer: Any) -> None:
    """The building's outer walls are inside the first frame (plan view, Fit all)."""
    box = viewer.page.locator(f"{ROOT} canvas").bounding_box()
    for x, y in viewer.api(f"projectXYZ({json.dumps(outer_corners_local(viewer.scene))})"):
        assert 0 <= x <= box["width"]
        assert 0 <= y <= box["height"]


def check_labels(viewer: Any) -> int:
    """Shown labels overlap none other and lie inside the stage; returns how many are shown."""
    settle(viewer)
    boxes = viewer.page.evaluate(
        f"""() => {{
          const root = document.querySelector('{ROOT}');
          const stage = root.querySelector('.lv-stage').getBoundingClientRect();
          const out = [];
          for (const n of root.querySelectorAll('.lv-label')) {{
            if (n.hidden || getComputedStyle(n).display === 'none') continue;
            const b = n.getBoundingClientRect();
            out.push([b.left - stage.left, b.top - stage.top, b.width, b.height,
                      stage.width, stage.height]);
          }}
          return out;
        }}"""
    )
    for x, y, w, h, sw, sh in boxes:
        assert x >= 0
        assert y >= 0
        assert x + w <= sw + 0.5
        assert y + h <= sh + 0.5
    for i, (x, y, w, h, _, _) in enumerate(boxes):
        for u, v, p, q, _, _ in boxes[i + 1 :]:
            assert x + w <= u or u + p <= x or y + h <= v or v + q <= y
    return len(boxes)


def check_fit_paths(viewer: Any) -> None:
    """Fit paths frames the paths alone (a larger scale); Fit all frames the building again."""
    viewer.page.locator(f"{ROOT} button[data-action=fit-paths]").click()
    settle(viewer)
    scale = viewer.page.locator(f"{ROOT} .lv-scale")
    paths_px_per_m = float(scale.get_attribute("data-scale-px")) / float(
        scale.get_attribute("data-scale-m")
    )
    viewer.page.locator(f"{ROOT} button[data-action=reset]").click()
    settle(viewer)
    all_px_per_m = float(scale.get_attribute("data-scale-px")) / float(
        scale.get_attribute("data-scale-m")
    )
    assert paths_px_per_m > all_px_per_m * 1.1


def check_stretch_click(viewer: Any, beyond: list[dict[str, object]]) -> None:
    """A click on the worst stretch: the timeline at its start, the view around it."""
    viewer.page.locator(f"{ROOT} .lv-beyond button[data-stretch='0']").click()
    root = viewer.page.locator(ROOT)
    assert float(root.get_attribute("data-time-s")) == pytest.approx(beyond[0]["t0_s"], abs=1e-6)
    assert json.loads(root.get_attribute("data-errors"))["slam"] > TOLERANCE_M
    stretch = viewer.scene["beyond"][0]
    points = viewer.api("project(1)")[stretch["i0"] : stretch["i1"] + 1]
    box = viewer.page.locator(f"{ROOT} canvas").bounding_box()
    xs, ys = zip(*points, strict=True)
    assert min(xs) >= 0
    assert max(xs) <= box["width"]
    assert min(ys) >= 0
    assert max(ys) <= box["height"]
    assert max(ys) - min(ys) > 0.3 * box["height"]  # zoomed in on it


def test_ifc_office(browser: Any, run: EvaluationResult, folder: Path, tmp_path: Path) -> None:
    """IFC: the stretches and rooms, their colours, the scale, the framing, a click, the labels."""
    path = tmp_path / "viewer.html"
    options = ExportOptions(building=folder / "office.ifc", title="Office, IFC")
    path.write_bytes(export_viewer_html(run, options))
    viewer = open_viewer(browser, path)
    assert viewer.scene["building"]["kind"] == "mesh"
    beyond = check_contract(viewer, run)
    check_walls_framed(viewer)
    viewer.shoot("viewer_office_ifc_plan.png", tmp_path)
    assert check_labels(viewer) >= 6  # the greatest errors, the rooms, axis numbers
    check_beyond_colours(viewer)
    corners = outer_corners_local(viewer.scene)
    check_scale_bar(viewer, corners[0:3], corners[6:9])
    check_fit_paths(viewer)
    check_stretch_click(viewer, beyond)
    viewer.shoot("viewer_office_ifc_stretch.png", tmp_path)
    check_labels(viewer)
    viewer.api("reset()")
    viewer.api("setView('orbit')")
    settle(viewer)
    assert viewer.page.locator(f"{ROOT} .lv-scale").is_hidden()
    axes = viewer.page.locator(f"{ROOT} .lv-axis:visible")
    assert axes.count() >= 4  # the labelled grid
    check_labels(viewer)
    viewer.shoot("viewer_office_ifc_3d.png", tmp_path)
    # a narrow page: the same guarantees at 420 px
    viewer.page.set_viewport_size({"width": 420, "height": 900})
    viewer.api("setView('plan')")
    viewer.api("reset()")
    settle(viewer)
    check_walls_framed(viewer)
    assert check_labels(viewer) >= 3
    viewer.shoot("viewer_office_ifc_420.png", tmp_path)
    viewer.assert_closed()


def test_dxf_office(browser: Any, run: EvaluationResult, folder: Path, tmp_path: Path) -> None:
    """DXF plan: the rooms from its labels; the scale bar matches the walls' drawn pixels."""
    path = tmp_path / "viewer.html"
    options = ExportOptions(building=folder / "office.dxf", title="Office, DXF plan")
    path.write_bytes(export_viewer_html(run, options))
    viewer = open_viewer(browser, path)
    assert viewer.scene["building"]["kind"] == "plan"
    check_contract(viewer, run)
    check_walls_framed(viewer)
    for k in range(len(viewer.scene["paths"])):
        viewer.api(f"showPath({k}, false)")
    pixels = viewer.canvas_pixels().astype(int)
    grey = np.abs(pixels - np.array([0x9A, 0xA3, 0xAD])).max(axis=2) <= 6  # the plan's lines
    ys, xs = np.nonzero(grey)
    settle(viewer)
    scale = viewer.page.locator(f"{ROOT} .lv-scale")
    px = float(scale.get_attribute("data-scale-px"))
    px_per_m = px / float(scale.get_attribute("data-scale-m"))
    # the outer faces of the east and west walls are 10.4 m apart: the drawn lines' span
    drawn_px_per_m = (xs.max() - xs.min()) / float(OUTER_MAX[0] - OUTER_MIN[0])
    assert px_per_m == pytest.approx(drawn_px_per_m, rel=0.02)
    drawn_px_per_m_y = (ys.max() - ys.min()) / float(OUTER_MAX[1] - OUTER_MIN[1])
    assert px_per_m == pytest.approx(drawn_px_per_m_y, rel=0.02)
    for k in range(len(viewer.scene["paths"])):
        viewer.api(f"showPath({k}, true)")
    assert check_labels(viewer) >= 4
    viewer.shoot("viewer_office_dxf_plan.png", tmp_path)
    viewer.assert_closed()


def test_glb_office_stands_upright(
    browser: Any, run: EvaluationResult, folder: Path, tmp_path: Path
) -> None:
    """A Z-up GLB read as glTF (Y up) lies on its side: the warning names the fix, which works."""
    glb = folder / "office.glb"
    path = tmp_path / "viewer.html"
    path.write_bytes(export_viewer_html(run, ExportOptions(building=glb, units=Units.M)))
    viewer = open_viewer(browser, path)
    (warning,) = viewer.scene["building_warnings"]
    assert "set --building-up to z" in warning
    assert viewer.page.locator(f"{ROOT} .lv-warning").inner_text() == warning
    lying = np.array(viewer.scene["building"]["positions"]).reshape(-1, 3)
    assert np.ptp(lying[:, 2]) == pytest.approx(OUTER_MAX[1] - OUTER_MIN[1], abs=1e-3)
    viewer.assert_closed()

    fixed = tmp_path / "viewer_z.html"
    options = ExportOptions(building=glb, units=Units.M, building_up=UpAxis.Z, title="Office, GLB")
    fixed.write_bytes(export_viewer_html(run, options))
    upright = open_viewer(browser, fixed)
    assert upright.scene["building_warnings"] == []
    assert upright.page.locator(f"{ROOT} .lv-warning").count() == 0
    standing = np.array(upright.scene["building"]["positions"]).reshape(-1, 3)
    assert np.ptp(standing[:, 2]) == pytest.approx(OFFICE_HEIGHT_M, abs=1e-3)
    footprint = np.ptp(standing[:, :2], axis=0)
    np.testing.assert_allclose(footprint, OUTER_MAX - OUTER_MIN, atol=1e-3)
    check_walls_framed(upright)
    # every wall's footprint corner projects inside the first frame
    base = upright.scene["base"]
    corners = [c for wall in OFFICE_WALLS for c in wall_corners(*wall)]
    xyz = [v for x, y in corners for v in (x - base[0], y - base[1], OFFICE_HEIGHT_M / 2)]
    box = upright.page.locator(f"{ROOT} canvas").bounding_box()
    for x, y in upright.api(f"projectXYZ({json.dumps(xyz)})"):
        assert 0 <= x <= box["width"]
        assert 0 <= y <= box["height"]
    upright.api("setView('orbit')")
    upright.shoot("viewer_office_glb_3d.png", tmp_path)
    upright.assert_closed()
