"""The viewer in headless Chromium (WebGL by SwiftShader): drawn where the data says, readable.

viewer.html and report.html are opened from ``file://``; the tests prove from the DOM and
from screenshots that the paths are drawn at their projected vertices in the reference's
colour and the ATE scale, the building is drawn, the timeline gives the stamp and error of
``errors.csv``, a click gives a point's figures, the console stays clean and no request is
made at all. Screenshots go to ``$LOCEVAL_SCREENSHOTS`` when set (else the test's tmp_path).
"""

from __future__ import annotations

import base64
import bisect
import csv
import io
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exporters.options import ExportOptions, Units
from exporters.report import render_report_html
from exporters.tables import export_errors_csv
from exporters.viewer import export_viewer_html
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from loceval.readers import read_trajectory
from loceval.registration.alignment import AlignMethod
from tests.conftest import skip_or_fail
from tests.exporters.viewer.test_viewer import scene_of

pytestmark = [pytest.mark.slow]

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
ROOT = ".loceval-viewer"
READY = ".loceval-viewer[data-ready='true']"


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """The system Chromium driven by Playwright, WebGL on SwiftShader."""
    if not CHROMIUM.is_file():
        skip_or_fail(f"{CHROMIUM} is not installed (apt package chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        skip_or_fail("the playwright package is not installed (pip install playwright)")
    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()


class Opened:
    """A viewer page opened from disk, with what its console said and what it requested."""

    def __init__(self, page: Any, path: Path) -> None:
        self.page = page
        self.path = path
        self.problems: list[str] = []
        self.requests: list[str] = []
        page.on("pageerror", lambda exc: self.problems.append(f"pageerror: {exc}"))
        page.on(
            "console",
            lambda m: (
                self.problems.append(f"{m.type}: {m.text}")
                if m.type in ("error", "warning")
                else None
            ),
        )
        page.on("request", lambda r: self.requests.append(r.url))
        page.goto(path.as_uri())
        page.wait_for_selector(READY, timeout=30_000)
        self.scene = scene_of(path.read_bytes())

    def api(self, call: str) -> Any:
        """Call the viewer's test interface (root.locevalViewer)."""
        return self.page.evaluate(f"document.querySelector('{ROOT}').locevalViewer.{call}")

    def canvas_pixels(self) -> np.ndarray:
        """Return the canvas as an (H, W, 3) uint8 array, after the next frame."""
        from PIL import Image

        # the WebGL canvas alone (its drawing buffer is kept), without the HTML labels over it
        url = self.page.evaluate(
            "new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => "
            f"r(document.querySelector('{ROOT} canvas').toDataURL('image/png')))))"
        )
        png = base64.b64decode(url.split(",", 1)[1])
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def shoot(self, name: str, tmp_path: Path) -> Path:
        """Save a screenshot of the page as ``name``."""
        folder = Path(os.environ.get("LOCEVAL_SCREENSHOTS", tmp_path))
        folder.mkdir(parents=True, exist_ok=True)
        out = folder / name
        self.page.screenshot(path=str(out))
        return out

    def assert_closed(self) -> None:
        """No console error or warning, and no request but the file itself."""
        assert self.problems == []
        assert self.requests == [self.path.as_uri()]


def open_viewer(browser: Any, path: Path) -> Opened:
    """Open ``path`` in a fresh 1200 x 800 page."""
    context = browser.new_context(viewport={"width": 1200, "height": 800})
    page = context.new_page()
    page.set_default_timeout(30_000)
    return Opened(page, path)


def hex_rgb(colour: str) -> np.ndarray:
    """``#rrggbb`` as an int array."""
    return np.array([int(colour[k : k + 2], 16) for k in (1, 3, 5)])


def share_at(pixels: np.ndarray, points: list[list[float]], colours: np.ndarray) -> float:
    """The share of on-screen vertices whose pixel has the colour of a vertex drawn there.

    A vertex is a dot of a few pixels; a neighbour within 3 px drawn later may cover it,
    so the pixel may take any colour of the vertices that project within 3 px of it.
    """
    from scipy.spatial import KDTree

    h, w, _ = pixels.shape
    screen = np.array(points)
    xy = np.floor(screen).astype(int)
    inside = (xy[:, 0] >= 0) & (xy[:, 0] < w) & (xy[:, 1] >= 0) & (xy[:, 1] < h)
    assert inside.mean() > 0.95  # the view fits the paths
    tree = KDTree(screen)
    hits = 0
    for i in np.flatnonzero(inside)[:: max(1, int(inside.sum()) // 400)]:  # 400 samples
        got = pixels[xy[i, 1], xy[i, 0]].astype(int)
        near = tree.query_ball_point(xy[i] + 0.5, 3.0)
        hits += bool(np.any(np.all(np.abs(colours[near] - got) <= 3, axis=1)))
    return hits / len(np.flatnonzero(inside)[:: max(1, int(inside.sum()) // 400)])


def bin_colours(scene: dict, errors: list[float]) -> np.ndarray:
    """The ATE scale's colour of each error (the bins' upper bounds are inclusive)."""
    highs = [b["high"] for b in scene["bins"][:-1]]
    which = [bisect.bisect_left(highs, e) for e in errors]
    return np.array([hex_rgb(scene["bins"][k]["color"]) for k in which])


def errors_by_estimate(result: EvaluationResult) -> dict[str, list[tuple[float, float]]]:
    """errors.csv as estimate -> [(t_s, ate_m)]."""
    text = export_errors_csv(result, ExportOptions()).decode("utf-8")
    out: dict[str, list[tuple[float, float]]] = {}
    for row in csv.DictReader(io.StringIO(text)):
        out.setdefault(row["estimate"], []).append((float(row["t_s"]), float(row["ate_m"])))
    return out


def length_text(scene: dict, value_m: float) -> str:
    """An error as the viewer prints it: the scene's unit of lengths (the one rule)."""
    unit = scene["lengths"]
    return f"{value_m * unit['per_metre']:.{unit['decimals']}f} {unit['symbol']}"


def check_paths_drawn(viewer: Opened) -> None:
    """Each path alone: its projected vertices carry its colour (reference) or the ATE scale."""
    paths = viewer.scene["paths"]
    for k, path in enumerate(paths):
        for j in range(len(paths)):
            viewer.api(f"showPath({j}, {str(j == k).lower()})")
        pixels = viewer.canvas_pixels()
        points = viewer.api(f"project({k})")
        if path["kind"] == "reference":
            colours = np.tile(hex_rgb(path["color"]), (len(points), 1))
        else:
            colours = bin_colours(viewer.scene, path["err"])
        share = share_at(pixels, points, colours)
        assert share > 0.9, (path["name"], share)
    for j in range(len(paths)):
        viewer.api(f"showPath({j}, true)")


def check_timeline(viewer: Opened, result: EvaluationResult, positions: list[int]) -> int:
    """Moving the slider: data-time-s is the reference's stamp, data-errors errors.csv's ATE.

    Returns how many (position, estimate) pairs had an error to compare.
    """
    table = errors_by_estimate(result)
    reference_t = viewer.scene["paths"][0]["t"]
    slider = viewer.page.locator(f"{ROOT} input[type=range]")
    root = viewer.page.locator(ROOT)
    compared = 0
    for i in positions:
        slider.fill(str(i))
        t = float(root.get_attribute("data-time-s"))
        assert t == pytest.approx(reference_t[i], abs=1e-9)
        errors = json.loads(root.get_attribute("data-errors"))
        readout = viewer.page.locator(f"{ROOT} .lv-readout").inner_text()
        assert f"t = {t:.3f} s" in readout
        for name, rows in table.items():
            times = np.array([r[0] for r in rows])
            nearest = int(np.argmin(np.abs(times - t)))
            if name in errors:
                assert errors[name] == rows[nearest][1], (name, t)
                assert abs(times[nearest] - t) < 1.0
                assert f"{name}: {length_text(viewer.scene, errors[name])}" in readout
                compared += 1
            else:  # no estimate there: before, after, or inside a break of its path
                path = next(p for p in viewer.scene["paths"] if p["name"] == name)
                j = bisect.bisect_right(path["t"], t) - 1
                assert j < 0 or j == len(path["t"]) - 1 or j in path["breaks"], (name, t)
    return compared


def check_click(viewer: Opened, k: int, i: int) -> None:
    """Clicking vertex i of path k shows its stamp, error and coordinates."""
    path = viewer.scene["paths"][k]
    for j in range(len(viewer.scene["paths"])):
        viewer.api(f"showPath({j}, {str(j == k).lower()})")
    x, y = viewer.api(f"project({k})")[i]
    box = viewer.page.locator(f"{ROOT} canvas").bounding_box()
    viewer.page.mouse.move(box["x"] + x, box["y"] + y)  # hovering shows the same figures
    tip = viewer.page.locator(f"{ROOT} .lv-tip")
    assert tip.is_visible()
    assert tip.inner_text().startswith(path["name"])
    viewer.page.mouse.click(box["x"] + x, box["y"] + y)
    info = viewer.page.locator(f"{ROOT} .lv-info")
    assert info.get_attribute("data-path") == path["name"]
    t = float(info.get_attribute("data-t-s"))
    j = path["t"].index(t)  # the clicked vertex or one drawn on the same pixel
    assert np.hypot(*(np.array(viewer.api(f"project({k})")[j]) - [x, y])) <= 1.0
    text = info.inner_text()
    assert f"t = {t:.3f} s" in text
    assert f"t = {t:.3f} s" in tip.inner_text()
    if path["kind"] == "estimate":
        assert float(info.get_attribute("data-error-m")) == path["err"][j]
        assert f"ATE = {length_text(viewer.scene, path['err'][j])}" in text
    base = viewer.scene["base"]
    digits = viewer.scene["coordinate_decimals"]  # to the millimetre in the model's units
    assert f"x = {path['xyz'][3 * j] + base[0]:.{digits}f} {viewer.scene['units']}" in text
    for j in range(len(viewer.scene["paths"])):
        viewer.api(f"showPath({j}, true)")


# --- the recordings -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fr2(public_data: Path) -> EvaluationResult:
    """ORB-SLAM (monocular, Sim(3)) against fr2_desk's motion-capture truth."""
    ref = read_trajectory(str(public_data / "fr2_desk_groundtruth.txt"))
    est = read_trajectory(str(public_data / "fr2_desk_ORB.txt"))
    return evaluate(ref, [est], EvaluationConfig(align=AlignMethod.SIM3))


@pytest.fixture(scope="module")
def nav2(public_data: Path) -> EvaluationResult:
    """AMCL and wheel odometry against tf map -> base_link in nav2_turtlebot."""
    bag = public_data / "nav2_turtlebot.mcap"
    ref = read_trajectory(f"{bag}@tf:map:base_link")
    return evaluate(ref, [read_trajectory(f"{bag}@/amcl_pose"), read_trajectory(f"{bag}@/odom")])


@pytest.mark.public_data
def test_excursions_are_drawn_and_labelled(browser: Any, tmp_path: Path) -> None:
    """A run that leaves the tracked room: its stretch outside is a purple line with its label.

    The label is shown at the first vertex outside, the line's colour is on the canvas only
    while the excursions' box is ticked, and unticking hides the label too.
    """
    from tests.loceval.metrics.test_excursions import _run

    reference, estimate, _ = _run()
    result = evaluate(reference, [estimate], EvaluationConfig(no_ci=True))
    path = tmp_path / "viewer.html"
    path.write_bytes(export_viewer_html(result, ExportOptions(title="excursion")))
    viewer = open_viewer(browser, path)
    (shown,) = viewer.scene["excursions"]
    label = viewer.page.locator(f"{ROOT} .lv-excursion")
    assert label.inner_text() == shown["label"]
    assert label.is_visible()
    purple = hex_rgb(viewer.scene["excursion_color"])

    def purple_pixels() -> int:
        pixels = viewer.canvas_pixels().astype(int)
        return int((np.abs(pixels - purple).max(axis=2) <= 3).sum())

    viewer.shoot("viewer_excursion.png", tmp_path)
    assert purple_pixels() > 50  # a dashed line of 45 m across most of the view
    viewer.page.locator(f"{ROOT} input[data-action=excursions]").uncheck()
    assert purple_pixels() == 0
    assert not label.is_visible()
    viewer.assert_closed()


def test_fr2_desk_viewer(browser: Any, fr2: EvaluationResult, tmp_path: Path) -> None:
    """fr2_desk: drawn where the data puts it; timeline and click give errors.csv's figures."""
    path = tmp_path / "viewer.html"
    path.write_bytes(export_viewer_html(fr2, ExportOptions(title="fr2_desk: ORB-SLAM")))
    viewer = open_viewer(browser, path)
    viewer.shoot("viewer_fr2_desk_plan.png", tmp_path)
    check_paths_drawn(viewer)
    n = len(viewer.scene["paths"][0]["t"])
    assert check_timeline(viewer, fr2, [0, n // 7, n // 3, n // 2, (4 * n) // 5, n - 1]) >= 4
    check_click(viewer, 1, len(viewer.scene["paths"][1]["t"]) // 3)
    check_click(viewer, 0, 10)
    viewer.api("setView('orbit')")
    viewer.shoot("viewer_fr2_desk_3d.png", tmp_path)
    viewer.assert_closed()


@pytest.mark.public_data
def test_nav2_viewer(browser: Any, nav2: EvaluationResult, tmp_path: Path) -> None:
    """nav2_turtlebot: AMCL and odometry against the tf chain, breaks where the data has them."""
    path = tmp_path / "viewer.html"
    path.write_bytes(export_viewer_html(nav2, ExportOptions(title="nav2: AMCL and odometry")))
    viewer = open_viewer(browser, path)
    check_paths_drawn(viewer)
    assert len(viewer.scene["paths"][0]["breaks"]) == 3  # the reference's 3 tracking losses
    n = len(viewer.scene["paths"][0]["t"])
    assert check_timeline(viewer, nav2, list(range(0, n, max(1, n // 12)))) >= 10
    viewer.page.locator(f"{ROOT} input[type=range]").fill(str(n // 2))
    # AMCL reports covariances: its 2-sigma ellipses appear with the Uncertainty box
    amcl = viewer.scene["paths"][1]
    assert amcl["uncertainty"] is not None
    assert viewer.scene["paths"][2]["uncertainty"] is None  # odometry reports none here

    def pinkish() -> int:  # the ellipses: magenta at 60 % over white, (255, 102, 255)
        p = viewer.canvas_pixels().astype(int)
        return int(np.sum((p[:, :, 0] > 200) & (p[:, :, 2] > 200) & (p[:, :, 1] < 180)))

    assert amcl["color"] == "#ff00ff"
    before = pinkish()
    viewer.page.locator(f"{ROOT} input[data-action=uncertainty]").check()
    assert pinkish() > before + 1000
    viewer.shoot("viewer_nav2_plan.png", tmp_path)
    check_click(viewer, 2, 40)
    viewer.assert_closed()


@pytest.mark.public_data
def test_report_has_the_viewer(browser: Any, fr2: EvaluationResult, tmp_path: Path) -> None:
    """report.html carries the same viewer under its CSP: ready, drawn, no request made."""
    path = tmp_path / "report.html"
    path.write_bytes(render_report_html(fr2, ExportOptions(title="fr2_desk report")))
    viewer = open_viewer(browser, path)
    viewer.page.locator("#viewer").scroll_into_view_if_needed()
    check_paths_drawn(viewer)
    viewer.page.locator("#viewer").screenshot(
        path=str(
            viewer.shoot("report_fr2_desk.png", tmp_path).with_name("report_viewer_fr2_desk.png")
        )
    )
    viewer.assert_closed()


def test_building_is_drawn(browser: Any, two_estimates: EvaluationResult, tmp_path: Path) -> None:
    """An IFC room is drawn as a see-through mesh under the paths (and no grid)."""
    pytest.importorskip("ifcopenshell")
    from tests.exporters.ifcfactory import GRID_CONVERSION, write_room

    room = write_room(tmp_path / "room.ifc", map_conversion=GRID_CONVERSION)
    path = tmp_path / "viewer.html"
    options = ExportOptions(building=room, units=Units.M, title="Room with a door")
    path.write_bytes(export_viewer_html(two_estimates, options))
    viewer = open_viewer(browser, path)
    assert viewer.scene["building"]["kind"] == "mesh"
    check_paths_drawn(viewer)
    for j in range(len(viewer.scene["paths"])):
        viewer.api(f"showPath({j}, false)")
    viewer.api("setView('orbit')")
    pixels = viewer.canvas_pixels().astype(int)
    white = np.all(pixels >= 250, axis=2)
    bluish = (pixels[:, :, 2] > pixels[:, :, 0] + 3) & ~white  # the mesh's blue-grey
    assert bluish.mean() > 0.05
    for j in range(len(viewer.scene["paths"])):
        viewer.api(f"showPath({j}, true)")
    viewer.shoot("viewer_building_3d.png", tmp_path)
    viewer.assert_closed()


def test_control_points_on_a_building(browser: Any, tmp_path: Path) -> None:
    """Control points over a see-through room: drawn at their places; a visit gives its error."""
    trimesh = pytest.importorskip("trimesh")
    from exporters.checkpoints import checkpoint_errors_csv
    from exporters.viewer.checkpoints import export_checkpoint_viewer_html
    from loceval.checkpoint_evaluation import CheckpointConfig, evaluate_control_points
    from tests.checkpoint_factory import grid_points, stop_and_go

    rec = stop_and_go(np.random.default_rng(7), grid_points(3, 4), passes=2)
    survey = evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(align_points=("P00", "P03", "P20", "P23")),
        reference_name="survey",
    )
    low, high = rec.points.positions_xyz.min(axis=0), rec.points.positions_xyz.max(axis=0)
    room = trimesh.creation.box(extents=(high[0] - low[0] + 0.6, high[1] - low[1] + 0.6, 2.4))
    room.apply_translation([(low[0] + high[0]) / 2, (low[1] + high[1]) / 2, 1.2])
    obj = tmp_path / "room.obj"
    room.export(obj)
    path = tmp_path / "viewer.html"
    options = ExportOptions(building=obj, units=Units.M, title="Survey of 12 control points")
    path.write_bytes(export_checkpoint_viewer_html(survey, options))
    viewer = open_viewer(browser, path)
    controls = viewer.scene["controls"]
    assert viewer.scene["building"]["kind"] == "mesh"

    # every control point: a black ring with a white centre at its projected place
    viewer.api("showPath(0, false)")
    pixels = viewer.canvas_pixels().astype(int)
    xyz = [c for p in controls["points"] for c in p["xyz"]]
    for x, y in viewer.api(f"projectXYZ({json.dumps(xyz)})"):
        patch = pixels[int(y) - 6 : int(y) + 7, int(x) - 6 : int(x) + 7].reshape(-1, 3)
        assert np.any(np.all(patch >= 250, axis=1)), (x, y)  # the white centre
        assert np.any(np.all(patch <= 40, axis=1)), (x, y)  # the black ring
    viewer.api("showPath(0, true)")

    # the timeline in a visit: data-errors holds that visit's error, as errors.csv has it
    rows = list(csv.DictReader(io.StringIO(checkpoint_errors_csv(survey).decode())))
    track = viewer.scene["paths"][0]
    slider = viewer.page.locator(f"{ROOT} input[type=range]")
    root = viewer.page.locator(ROOT)
    checked = 0
    for visit, row in list(zip(controls["visits"], rows, strict=True))[::5]:
        i = bisect.bisect_left(track["t"], (visit["t0"] + visit["t1"]) / 2)
        slider.fill(str(i))
        errors = json.loads(root.get_attribute("data-errors"))
        assert errors == {track["name"]: float(row["error_m"])}
        checked += 1
    assert checked >= 4
    viewer.api("setView('orbit')")
    viewer.shoot("viewer_control_points_building_3d.png", tmp_path)
    viewer.api("setView('plan')")
    viewer.shoot("viewer_control_points_building_plan.png", tmp_path)
    viewer.assert_closed()

    # the control-point report carries the same viewer, allowed by its CSP
    from exporters.report.checkpoints import render_checkpoint_report

    report = tmp_path / "report.html"
    report.write_bytes(render_checkpoint_report(survey, options, pdf=False)[0])
    in_report = open_viewer(browser, report)
    assert in_report.scene["controls"]["visits"] == controls["visits"]
    in_report.assert_closed()
