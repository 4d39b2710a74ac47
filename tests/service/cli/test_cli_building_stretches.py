"""The command line on the building: the stretches beyond the tolerance with their rooms.

``loceval evaluate`` with a tolerance and an IFC office prints each stretch as a site
engineer says it ("#1 beyond 0.025 m for 3.5 s in 2.14 Office"), and ``result.json``
carries the same stretches with their spaces and the building's spaces; a Z-up GLB read as
glTF prints the warning with the flag to set.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli import main
from tests.exporters.office import office_run, write_office, write_office_glb
from tests.factories import write_tum


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The office run as TUM files, the office as IFC and as a Z-up GLB."""
    pytest.importorskip("ifcopenshell")
    folder = tmp_path_factory.mktemp("office")
    truth, estimate, _ = office_run()
    return {
        "truth": write_tum(folder / "truth.txt", truth),
        "slam": write_tum(folder / "slam.txt", estimate),
        "ifc": write_office(folder / "office.ifc"),
        "glb": write_office_glb(folder / "office.glb"),
    }


def test_stretches_and_rooms(
    recording: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The tables list the stretches with their rooms; result.json has them and the spaces."""
    code = main(
        ["evaluate", str(recording["truth"]), str(recording["slam"]), "--name", "slam",
         "--align", "none", "--tolerance", "0.025@95", "--no-ci", "--building",
         str(recording["ifc"]), "--out", str(tmp_path / "out"), "--formats", "result.json"]
    )  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0
    document = json.loads((tmp_path / "out" / "result.json").read_text())
    spans = document["estimates"][0]["verdict"]["failing_spans"]
    assert [s["space"] for s in spans] == ["2.14 Office", "2.14 Office"]
    assert [s["max_error_m"] for s in spans] == pytest.approx([0.060, 0.045], abs=1e-6)
    first = spans[0]
    line = (
        f"  #1 beyond 0.025 m for {first['duration_s']:.1f} s in 2.14 Office: from t = "
        f"{first['start_s']:.1f} s, {first['length_m']:.1f} m travelled, worst 60.0 mm"
    )
    assert line in out.splitlines()
    assert [s["name"] for s in document["building"]["spaces"]] == ["2.13 Meeting", "2.14 Office"]
    assert document["building"]["warnings"] == []
    # the statistics tables of sub-decimetre errors read in millimetres (one rule)
    rmse = next(line for line in out.splitlines() if line.startswith("RMSE"))
    assert rmse.endswith(" mm")


def test_a_glb_on_its_side_is_named(
    recording: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """--json with a Z-up GLB: the building's warning names --building-up z."""
    code = main(
        ["evaluate", str(recording["truth"]), str(recording["slam"]), "--align", "none",
         "--tolerance", "0.025@95", "--no-ci", "--units", "m", "--building",
         str(recording["glb"]), "--json"]
    )  # fmt: skip
    assert code == 0
    document = json.loads(capsys.readouterr().out)
    (warning,) = document["building"]["warnings"]
    assert "set --building-up to z" in warning
