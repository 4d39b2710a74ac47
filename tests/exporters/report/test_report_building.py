"""The report on the building: stretches with their rooms, the tolerance in words, honest captions.

The office run (:mod:`tests.exporters.office`) fails a 0.025 m tolerance in two stretches,
both in ``2.14 Office``; the report's view model (which the HTML and the PDF templates
render) lists them with their rooms and says where in the building the system fails, the
legend names the tolerance, a misplaced building's warning reaches the report, and a plan
figure mentions the building only when some of it is drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from exporters.options import ExportOptions, Units, UpAxis
from exporters.plots.underlay import draw_floor_plan, floor_plan_note
from exporters.report import render_report_html
from exporters.report.view import build_report_view
from loceval.evaluation import EvaluationResult
from tests.exporters.office import (
    evaluate_office,
    write_office,
    write_office_glb,
    write_office_plan,
)


@pytest.fixture(scope="module")
def run() -> EvaluationResult:
    """The office run against 0.025 m @ 95 %, no alignment."""
    return evaluate_office()


@pytest.mark.parametrize("kind", ["ifc", "dxf"])
def test_stretches_with_their_rooms(run: EvaluationResult, tmp_path: Path, kind: str) -> None:
    """Each listed stretch names its room, length and duration; the verdict says where."""
    pytest.importorskip("ifcopenshell")
    building = (
        write_office(tmp_path / "office.ifc")
        if kind == "ifc"
        else write_office_plan(tmp_path / "office.dxf")
    )
    view = build_report_view(run, ExportOptions(building=building), plots=())
    (verdict,) = view.verdicts
    spans = run.estimates[0].verdict.failing_spans  # type: ignore[union-attr]
    assert [s.space for s in verdict.spans] == ["2.14 Office", "2.14 Office"]
    assert verdict.spaces
    assert [s.length_m for s in verdict.spans] == [f"{s.length_m:.1f}" for s in spans]
    assert (
        verdict.spans[0].words == f"beyond 0.025 m for {spans[0].duration_s:.1f} s in 2.14 Office"
    )
    # the worst errors (0.060 m, 0.045 m) are one group below 0.1 m: millimetres to a tenth
    assert verdict.error_unit == "mm"
    assert [s.max_error_m for s in verdict.spans] == ["60.0", "45.0"]
    total = sum(s.duration_s for s in spans)
    assert f"Where, in the building: 2.14 Office (2 stretches, {total:.1f} s)." in verdict.details
    assert "within 0.025 m for 95 % of poses" in view.legend
    assert view.building is not None
    assert view.building.source == building.name
    assert view.building.spaces.startswith("2 named spaces (")
    assert view.building.warnings == ()


def test_a_building_on_its_side_is_reported(run: EvaluationResult, tmp_path: Path) -> None:
    """A Z-up GLB read as glTF (Y up): the report warns and names the value to set."""
    glb = write_office_glb(tmp_path / "office.glb")
    view = build_report_view(run, ExportOptions(building=glb, units=Units.M), plots=())
    assert view.building is not None
    (warning,) = view.building.warnings
    assert "set --building-up to z" in warning
    assert ("building model", warning) in view.warnings
    fixed = ExportOptions(building=glb, units=Units.M, building_up=UpAxis.Z)
    assert build_report_view(run, fixed, plots=()).building.warnings == ()  # type: ignore[union-attr]


def test_the_html_report_lists_rooms_and_the_legend(run: EvaluationResult, tmp_path: Path) -> None:
    """report.html: the stretches' table has the room column, the legend line the tolerance."""
    pytest.importorskip("ifcopenshell")
    ifc = write_office(tmp_path / "office.ifc")
    html = render_report_html(run, ExportOptions(building=ifc, title="office")).decode("utf-8")
    assert '<th scope="col">room</th>' in html
    assert html.count("<td>2.14 Office</td>") == 2
    assert "Tolerance: within 0.025 m for 95 % of poses." in html
    assert "Placed on the building model" in html
    assert "Grey lines: the building model cut at the device" in html  # drawn: the office


def test_a_caption_claims_no_building_it_did_not_draw() -> None:
    """A campus far larger than the paths and away from them: not in the figure, not claimed."""
    paths_xy = np.array([[0.0, 0.0], [5.0, 3.0]])
    ax = Figure().add_subplot()
    far = np.array([[[1000.0, 1000.0], [3000.0, 1000.0]], [[3000.0, 1000.0], [3000.0, 2000.0]]])
    assert draw_floor_plan(ax, far, paths_xy) is False
    assert floor_plan_note(drawn=False) == ""
    ax = Figure().add_subplot()
    around = np.array([[[-1.0, -1.0], [6.0, -1.0]], [[6.0, -1.0], [6.0, 4.0]]])
    assert draw_floor_plan(ax, around, paths_xy) is True
    assert "Grey lines" in floor_plan_note(drawn=True)
    # framed: the building's extent is in the axes' data limits
    assert ax.dataLim.x0 <= -1.0
    assert ax.dataLim.x1 >= 6.0
