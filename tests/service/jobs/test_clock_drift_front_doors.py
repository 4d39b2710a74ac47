"""The clock drift option on the CLI, the API and the options document; its report section."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from service.cli import main
from tests.calibration_factory import Motion
from tests.clock_factory import ClockTruth, DriftRecording, make_drifting_recording
from tests.factories import write_tum
from tests.service._api_fixtures import assert_problem, open_api

CLOCK = ClockTruth(offset_s=0.020, rate_ppm=-300.0)
"""150 s at -300 ppm: the offset moves by 45 ms over the run."""


@pytest.fixture(scope="module")
def recording() -> DriftRecording:
    """A 150 s handheld recording whose estimate's clock runs 300 ppm slow."""
    return make_drifting_recording(np.random.default_rng(42), CLOCK, duration_s=150.0)


@pytest.fixture(scope="module")
def files(recording: DriftRecording, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The recording as TUM files (reference, estimate)."""
    folder = tmp_path_factory.mktemp("drift")
    return (
        write_tum(folder / "truth.txt", recording.reference),
        write_tum(folder / "tag.txt", recording.estimate),
    )


def _first(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, object]:
    assert main(list(argv)) == 0
    doc: dict[str, object] = json.loads(capsys.readouterr().out)
    estimates = doc["estimates"]
    assert isinstance(estimates, list)
    first: dict[str, object] = estimates[0]
    return first


def test_cli_auto_applies_the_drift_and_the_report_draws_it(
    files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--clock-drift auto: the rate in result.json, the words and the plot in the report."""
    ref, est = files
    out = tmp_path / "out"
    doc = _first(
        capsys, "evaluate", str(ref), str(est), "--time-offset", "auto", "--clock-drift", "auto",
        "--json", "--no-ci", "--out", str(out), "--formats", "report.html",
    )  # fmt: skip
    clock = doc["time_offset"]
    assert isinstance(clock, dict)
    assert clock["rate_source"] == "estimated"
    assert clock["rate_ppm"] == pytest.approx(CLOCK.rate_ppm, abs=5.0)
    assert abs(clock["rate_ppm"] - CLOCK.rate_ppm) <= 3 * clock["sigma_rate_ppm"]
    assert clock["value_s"] == pytest.approx(CLOCK.offset_s, abs=0.001)
    html = (out / "report.html").read_text()
    section = re.search(r'<section id="clocks".*?</section>', html, re.DOTALL)
    assert section is not None
    text = section.group(0)
    assert 'data-plot="clock_drift"' in text
    assert "Clock drift estimated (1 sigma)" in text
    assert re.search(r"Its clock runs 29\d(\.\d+)? ± \d+(\.\d+)? ppm slow", text)
    assert "The estimated rate was applied along the run" in text
    assert "estimated from the motion, with any step" in html  # the options table


def test_cli_default_warns_with_the_option_to_set(
    files: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """Without the option the drift is checked: a warning in ms naming --clock-drift auto."""
    ref, est = files
    doc = _first(capsys, "evaluate", str(ref), str(est), "--time-offset", "auto", "--json")
    warnings = doc["warnings"]
    assert isinstance(warnings, list)
    drift = [w for w in warnings if w.startswith("The estimate's clock runs")]
    assert len(drift) == 1
    assert re.search(r"moves by 4\d\.\d ms over the 2\.\d min run", drift[0])
    assert "--clock-drift auto" in drift[0]
    clock = doc["time_offset"]
    assert isinstance(clock, dict)
    assert clock["rate_ppm"] == 0.0
    assert clock["estimated_rate_ppm"] == pytest.approx(CLOCK.rate_ppm, abs=10.0)


def test_cli_bad_values_exit_1(
    files: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """A word that is not auto, or a rate beyond 1000 ppm, is refused with exit code 1."""
    ref, est = files
    with pytest.raises(SystemExit) as stop:
        main(["evaluate", str(ref), str(est), "--clock-drift", "soon"])
    assert stop.value.code == 1
    assert "--clock-drift: takes a number or auto, got 'soon'" in capsys.readouterr().err
    assert main(["evaluate", str(ref), str(est), "--clock-drift", "5000"]) == 1
    err = capsys.readouterr().err
    assert "clock drift must be a finite number of ppm" in err
    assert "at most 1000, got 5000" in err


def test_api_auto_and_the_options_document(files: tuple[Path, Path], tmp_path: Path) -> None:
    """Over HTTP ``clock_drift_ppm: "auto"`` reaches the result; /options describes it."""
    ref, est = files
    with open_api(tmp_path) as api:
        options = api.client.get("/api/v1/options", headers=api.headers).json()
        spec = next(o for o in options["items"] if o["key"] == "clock_drift_ppm")
        assert spec["auto"] is True
        assert spec["flag"] == "--clock-drift"
        assert spec["bounds"] == "at least -1000 and at most 1000"
        ref_id = api.dataset("truth.txt", ref.read_bytes())["id"]
        est_id = api.dataset("tag.txt", est.read_bytes())["id"]
        body = {
            "reference": {"dataset_id": ref_id},
            "estimates": [{"dataset_id": est_id}],
            "options": {"formats": ["result.json"], "clock_drift_ppm": "auto", "no_ci": True},
        }
        evaluation = api.evaluate(body).json()
        assert evaluation["status"] == "succeeded", evaluation
        url = f"/api/v1/evaluations/{evaluation['id']}/artifacts/result.json"
        result = api.client.get(url, headers=api.headers).json()
        clock = result["estimates"][0]["time_offset"]
        assert clock["rate_source"] == "estimated"
        assert clock["rate_ppm"] == pytest.approx(CLOCK.rate_ppm, abs=5.0)
        assert result["options"]["auto_clock_drift"] is True


@pytest.mark.parametrize(
    ("value", "detail"),
    [
        ("soon", r"options\.clock_drift_ppm: .*or 'auto', got 'soon'"),
        (5000, r"options\.clock_drift_ppm: .*less than or equal to 1000"),
    ],
)
def test_api_bad_values_are_422(tmp_path: Path, value: object, detail: str) -> None:
    """A clock drift that is neither a number within bounds nor ``auto``: 422."""
    with open_api(tmp_path) as api:
        body = {
            "reference": {"dataset_id": "R"},
            "estimates": [{"dataset_id": "E"}],
            "options": {"formats": ["result.json"], "clock_drift_ppm": value},
        }
        assert_problem(api.evaluate(body), 422, detail=detail)


def test_cli_lists_the_quiet_check_under_notes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A repeating loop whose given offset the data fit: a note, printed apart from warnings."""
    loop = make_drifting_recording(
        np.random.default_rng(2), ClockTruth(offset_s=0.0), motion=Motion.LOOP, duration_s=300.0
    )
    ref = write_tum(tmp_path / "truth.txt", loop.reference)
    est = write_tum(tmp_path / "robot.txt", loop.estimate)
    assert main(["evaluate", str(ref), str(est), "--no-ci"]) == 0
    out = capsys.readouterr().out
    notes = out.split("\nNotes\n", 1)[1].split("\nWarnings\n", 1)[0]
    assert "The motion repeats, so" in notes
    assert "the given 0 s is one of them" in notes
    warnings = out.split("\nWarnings\n", 1)[1] if "\nWarnings\n" in out else ""
    assert "The motion repeats" not in warnings
