"""The report's intervals (Tables 1-2), comparisons in words and NEES table."""

from __future__ import annotations

import numpy as np
import pytest

from exporters import ExportOptions
from exporters.report import build_report_view
from exporters.report.render import DEFAULT_TEMPLATES_DIR, render_view_html
from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
from loceval.trajectory import Trajectory
from tests.exporters.conftest import noisy, walk


def _html(result: EvaluationResult) -> str:
    view = build_report_view(result, ExportOptions(), plots=())
    return render_view_html(view, templates_dir=DEFAULT_TEMPLATES_DIR).decode("utf-8")


def test_tables_show_intervals_and_verdict_states_comparisons(
    two_estimates: EvaluationResult,
) -> None:
    """Each RMSE reads "0.194 m (0.180–0.210)"; the verdict says which system is better."""
    html = _html(two_estimates)
    e = two_estimates.estimates[0]
    assert e.assessment is not None
    lo, hi = e.assessment.intervals["ate_translation"].ci95["rmse"]
    rmse = e.ate_translation.stats.rmse
    assert f"{rmse:.3f} m ({lo:.3f}–{hi:.3f})" in html
    assert "95 % confidence interval (moving-block bootstrap" in html
    assert two_estimates.comparisons
    for comparison in two_estimates.comparisons:
        assert comparison.summary.replace("'", "&#39;") in html
    assert 'id="comparisons"' in html
    assert 'id="consistency"' not in html  # no estimate reports a covariance


def test_comparison_sentence_names_the_better_system(rng: np.random.Generator) -> None:
    """A clearly better system is named as such in the verdict section."""
    truth = walk(rng, n=3000)
    good = noisy(rng, truth, every=1, sigma=0.01, drift=0.0, name="Good")
    poor = noisy(rng, truth, every=1, sigma=0.06, drift=0.0, name="Poor")
    html = _html(evaluate(truth, [good, poor]))
    assert "Good&#39;s ATE is lower than Poor&#39;s: difference" in html


def test_no_ci_report_says_intervals_are_off(two_estimates: EvaluationResult) -> None:
    """Without intervals the cells hold the bare values and the note says why."""
    result = evaluate(
        two_estimates.reference,
        [e.estimate for e in two_estimates.estimates],
        EvaluationConfig(no_ci=True),
    )
    html = _html(result)
    assert "Confidence intervals were turned off" in html
    assert 'id="comparisons"' not in html
    rmse = result.estimates[0].ate_translation.stats.rmse
    assert f"{rmse:.3f} m (" not in html


def test_nees_table_and_undecided_verdict(rng: np.random.Generator) -> None:
    """A reported covariance gets a NEES row; a straddling share reads undecided."""
    truth = walk(rng, n=3000)
    est = noisy(rng, truth, every=1, sigma=0.02, drift=0.0, name="AMCL").without_orientation()
    cov = np.zeros((len(est), 6, 6))
    cov[:, :3, :3] = 0.02**2 * np.eye(3)
    est = Trajectory(est.stamps_ns, est.positions_xyz, name="AMCL", cov6=cov)
    probe = evaluate(truth, [est]).estimates[0].ate_translation.values
    distance = float(np.quantile(probe, 0.9))
    result = evaluate(truth, [est], EvaluationConfig(tolerance=Tolerance(distance, 0.9)))
    view = build_report_view(result, ExportOptions(), plots=())
    (verdict,) = view.verdicts
    assert (verdict.status, verdict.badge) == ("undecided", "UNDECIDED")
    assert verdict.headline.startswith("AMCL: undecided: ")
    (row,) = view.confidence.consistency
    consistency = result.estimates[0].assessment
    assert consistency is not None
    assert consistency.consistency is not None
    nees = consistency.consistency.nees_position
    assert (row.name, row.block, row.dof) == ("AMCL", "position", "3")
    assert row.mean == f"{nees.mean:.2f}"
    assert row.verdict == nees.verdict.value
    html = render_view_html(view, templates_dir=DEFAULT_TEMPLATES_DIR).decode("utf-8")
    assert 'id="consistency"' in html
    assert "badge-undecided" in html


@pytest.mark.parametrize("column", [0, 1, 5])
def test_suffix_outside_the_table_is_empty(two_estimates: EvaluationResult, column: int) -> None:
    """Rows without intervals (STD, MIN, MAX) and unknown columns get no text."""
    view = build_report_view(two_estimates, ExportOptions(), plots=())
    assert view.confidence.suffix(1, "translation", "STD", column) == ""
    expected = column < len(two_estimates.estimates)
    assert (view.confidence.suffix(1, "translation", "RMSE", column) != "") is expected
