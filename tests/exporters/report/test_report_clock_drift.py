"""The report's clock section on a drifting clock: rows, words and the plot along the run."""

from __future__ import annotations

import re

import numpy as np
import pytest

from exporters.options import ExportOptions
from exporters.plots.clock import plot_clock_drift
from exporters.report import build_report_view
from exporters.report.clocks import drift_words
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from tests.calibration_factory import make_recording
from tests.clock_factory import ClockTruth, make_drifting_recording


@pytest.fixture(scope="module")
def drifting() -> EvaluationResult:
    """150 s, -300 ppm and a 40 ms step at 80 s; the drift checked, not applied."""
    rec = make_drifting_recording(
        np.random.default_rng(42),
        ClockTruth(offset_s=0.02, rate_ppm=-300.0, step_at_s=80.0, jump_s=0.040),
        duration_s=150.0,
    )
    return evaluate(rec.reference, [rec.estimate], EvaluationConfig(no_ci=True))


def _rows(view_rows: tuple[tuple[str, tuple[str, ...]], ...]) -> dict[str, str]:
    return {label: values[0] for label, values in view_rows}


def test_rows_words_and_plot_of_a_drift_not_applied(drifting: EvaluationResult) -> None:
    """The drift's rows, a sentence that says it was not corrected, and the plot after Fig. N."""
    view = build_report_view(drifting, ExportOptions())
    section = view.clocks
    rows = _rows(section.rows)
    assert rows["Clock drift given"] == "+0 ppm"
    found = re.fullmatch(
        r"([-+]\d+(?:\.\d+)?) ± (\d+(?:\.\d+)?) ppm", rows["Clock drift estimated (1 sigma)"]
    )
    assert found is not None
    rate, sigma = float(found[1]), float(found[2])
    assert abs(rate + 300.0) <= 3 * sigma
    step = rows["Clock steps found (offset change at time)"]
    assert re.fullmatch(r"-(39|40)\.\d ± 0\.\d ms at (79|80)\.\d+ ± 0\.\d+ s", step)
    assert rows["Clock drift applied"] == "none"
    ((name, words), *_rest) = section.drift
    assert name == "estimate"
    assert re.match(r"Its clock runs 29\d(\.\d+)? ± \d+(\.\d+)? ppm slow", words)
    assert "ppm slow against the ground truth's" in words
    assert re.search(r"its clock jumped ahead by (39|40)\.\d", words)
    assert words.endswith("This was not corrected: one offset was applied to the whole run.")
    assert section.figure is not None
    assert section.drift_figure is not None
    assert section.drift_figure.key == "clock_drift"
    assert section.drift_figure.number == section.figure.number + 1
    assert section.drift_figure.src.startswith("data:image/svg+xml;base64,")


def test_applied_drift_says_so(drifting: EvaluationResult) -> None:
    """With ``auto`` the sentence names the rate and the steps as applied."""
    result = evaluate(
        drifting.reference,
        [drifting.estimates[0].estimate],
        EvaluationConfig(no_ci=True, auto_clock_drift=True),
    )
    e = result.estimates[0]
    words = drift_words(e, result.config)
    assert words.endswith("The estimated rate and the steps were applied along the run.")
    rows = _rows(build_report_view(result, ExportOptions(), plots=()).clocks.rows)
    assert rows["Clock drift given"] == "auto (estimated)"
    assert rows["Clock drift applied"].endswith(" ppm and 1 step")


def test_short_run_has_no_drift_plot(rng: np.random.Generator) -> None:
    """A 40 s run is too short for a drift: no plot, and words that say why."""
    rec = make_recording(rng, duration_s=40.0)
    result = evaluate(rec.reference, [rec.estimate], EvaluationConfig(no_ci=True))
    assert plot_clock_drift(result) is None
    section = build_report_view(result, ExportOptions(), plots=()).clocks
    assert section.drift_figure is None
    assert section.drift[0][1].startswith("The run is too short, or moves too little")
    assert _rows(section.rows)["Clock drift estimated (1 sigma)"] == "not checked"
