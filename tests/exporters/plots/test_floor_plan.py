"""The building's floor plan under the report's plan-view plots."""

from __future__ import annotations

import base64
import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from exporters.options import ExportOptions
from loceval.checkpoint_evaluation import CheckpointConfig, evaluate_control_points
from loceval.evaluation import EvaluationConfig, EvaluationResult
from loceval.registration.alignment import AlignMethod
from tests.checkpoint_factory import grid_points, stop_and_go

pytest.importorskip("trimesh")
ezdxf = pytest.importorskip("ezdxf")
pytest.importorskip("ifcopenshell")

from exporters.cad import gltf  # noqa: E402
from exporters.plots import render_plots  # noqa: E402  (after the importorskip of its libraries)
from exporters.plots.underlay import FLOOR_PLAN_GID, floor_plan_segments  # noqa: E402
from exporters.report import render_report  # noqa: E402
from exporters.report.checkpoints import build_checkpoint_view  # noqa: E402
from tests.exporters.ifcfactory import GRID_CONVERSION, ROOM_X_M, ROOM_Y_M, WALL_M, write_room  # noqa: E402


def floor_plan_paths(svg: bytes) -> list[str]:
    """Return the segments drawn in the SVG's floor-plan group, ``"x0 y0 x1 y1"`` each.

    matplotlib writes one ``<path>`` a segment; the figure kit one path whose pieces each
    start with ``M`` and run on through the segments that meet (implicit line-tos).
    """
    text = svg.decode()
    match = re.search(rf'<g id="{FLOOR_PLAN_GID}">(.*?)</g>', text, flags=re.DOTALL)
    if match is None:
        return []
    drawn = []
    for data in re.findall(r'<path d="([^"]*)"', match.group(1)):
        for piece in re.findall(r"M([^M]*)", data):
            numbers = re.findall(r"-?[\d.]+", piece)
            points = [f"{x} {y}" for x, y in zip(numbers[::2], numbers[1::2], strict=True)]
            drawn.extend(f"{a} {b}" for a, b in itertools.pairwise(points))
    return drawn


def test_ifc_room_is_the_floor_plan_of_the_paths(
    tmp_path: Path, two_estimates: EvaluationResult
) -> None:
    """A georeferenced IFC room, cut at the walk's median height, lies under Fig. 1 and 2."""
    room = write_room(tmp_path / "room.ifc", map_conversion=GRID_CONVERSION)
    options = ExportOptions(building=room)
    segments = floor_plan_segments(two_estimates.reference.positions_xyz[:, 2], options)
    assert segments is not None
    # the walk's heights are 1.2-1.4 m, the walls 0..3 m: every wall face is cut; the IFC's
    # own coordinates are the evaluation frame (its conversion places both), so the cut
    # spans the walls' outer faces -0.2..6.2 x -0.2..4.2 m (ifcfactory's room)
    lo, hi = segments.reshape(-1, 2).min(axis=0), segments.reshape(-1, 2).max(axis=0)
    np.testing.assert_allclose(lo, [-WALL_M, -WALL_M], atol=1e-6)
    np.testing.assert_allclose(hi, [ROOM_X_M + WALL_M, ROOM_Y_M + WALL_M], atol=1e-6)
    plots = render_plots(two_estimates, formats=("svg",), floor_plan=segments)
    assert [p.key for p in plots[:3]] == ["overlay_xy", "ate_path_0", "ate_path_1"]
    for plot in plots[:3]:
        assert plot.svg is not None
        drawn = floor_plan_paths(plot.svg)
        assert len(drawn) == len(segments) > 0
        # every path is one segment; equal aspect: the drawn plan has the room's proportions
        ends = np.array([[float(v) for v in re.findall(r"-?[\d.]+", d)] for d in drawn])
        assert ends.shape == (len(segments), 4)
        width, height = np.ptp(ends[:, [0, 2]]), np.ptp(ends[:, [1, 3]])
        assert width / height == pytest.approx(
            (ROOM_X_M + 2 * WALL_M) / (ROOM_Y_M + 2 * WALL_M), rel=0.01
        )
    # the other plots (time series, CDF, side views) are not plans
    assert all(p.svg is not None and not floor_plan_paths(p.svg) for p in plots[3:])
    plain = render_plots(two_estimates, formats=("svg",))
    assert plain[0].svg is not None
    assert floor_plan_paths(plain[0].svg) == []


@pytest.mark.pdf
def test_report_pdf_and_html_carry_the_floor_plan(
    tmp_path: Path, two_estimates: EvaluationResult
) -> None:
    """The report (HTML and PDF) is rendered over the IFC room given as the building."""
    room = write_room(tmp_path / "room.ifc", map_conversion=GRID_CONVERSION)
    html, pdf = render_report(two_estimates, options=ExportOptions(building=room))
    assert pdf.startswith(b"%PDF")
    (tmp_path / "report.pdf").write_bytes(pdf)
    uris = re.findall(rb'src="data:image/svg\+xml;base64,([^"]+)"', html)
    assert uris
    fig1 = base64.b64decode(uris[0])
    assert len(floor_plan_paths(fig1)) > 0


def test_dxf_floor_plan_under_the_overlay(tmp_path: Path, two_estimates: EvaluationResult) -> None:
    """A DXF floor plan in millimetres is drawn as it is, placed by the inverse site."""
    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 4  # millimetres
    doc.modelspace().add_lwpolyline(
        [(-5000, -3000), (5000, -3000), (5000, 3000), (-5000, 3000)], close=True
    )
    plan = tmp_path / "plan.dxf"
    doc.saveas(plan)
    segments = floor_plan_segments(np.array([1.3]), ExportOptions(building=plan))
    assert segments is not None
    assert len(segments) == 4
    np.testing.assert_allclose(segments.reshape(-1, 2).min(axis=0), [-5.0, -3.0])
    plot = render_plots(two_estimates, formats=("svg",), floor_plan=segments)[0]
    assert plot.svg is not None
    assert len(floor_plan_paths(plot.svg)) == 4


def test_no_building_no_floor_plan() -> None:
    """Without a building model there is nothing to cut."""
    assert floor_plan_segments(np.array([1.3]), ExportOptions()) is None


def test_checkpoint_plan_over_a_floor_plan(rng: np.random.Generator, tmp_path: Path) -> None:
    """The control-point plan of the checkpoint report is drawn over a DXF floor plan."""

    rec = stop_and_go(rng, grid_points(3, 4), passes=1)
    evaluation = evaluate_control_points(
        rec.points, [rec.estimate], EvaluationConfig(align=AlignMethod.NONE), CheckpointConfig()
    )
    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 6  # metres
    doc.modelspace().add_lwpolyline([(-0.1, -0.1), (1.0, -0.1), (1.0, 0.7)])  # two walls
    plan = tmp_path / "plan.dxf"
    doc.saveas(plan)
    view = build_checkpoint_view(evaluation, ExportOptions(building=plan))
    (section,) = view.estimates
    svg = base64.b64decode(section.figure[0].split(",", 1)[1])
    assert len(floor_plan_paths(svg)) == 2
    assert "Grey lines" in section.figure[2]
    plain = build_checkpoint_view(evaluation, ExportOptions())
    assert floor_plan_paths(base64.b64decode(plain.estimates[0].figure[0].split(",", 1)[1])) == []


def test_glb_skips_a_dxf_floor_plan(tmp_path: Path, two_estimates: EvaluationResult) -> None:
    """A DXF plan is no mesh: the GLB has no building node and says why in its extras."""
    doc = ezdxf.new()
    doc.modelspace().add_line((0, 0), (1, 0))
    plan = tmp_path / "plan.dxf"
    doc.saveas(plan)
    glb = gltf.export_glb(two_estimates, ExportOptions(building=plan))
    assert b'"building"' not in glb
    assert b"plan.dxf is a 2D floor plan, not in the scene" in glb
