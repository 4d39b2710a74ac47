"""A schedule summary compares systems across runs (unpaired block bootstrap of per-run RMSE)."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from exporters.summary import SummaryInput, SummaryRun, SystemFigures, build_summary_view
from loceval.assessment.comparison import ComparedMetric, compare_runs
from loceval.errors import InputError

MONDAY = dt.datetime(2026, 11, 16, 9, 0, tzinfo=dt.UTC)


def _runs(ate: dict[str, np.ndarray], rpe: float = 0.01) -> list[SummaryRun]:
    count = len(next(iter(ate.values())))
    return [
        SummaryRun(
            dataset=f"level2-walk-{k:02d}",
            recorded_at=MONDAY + dt.timedelta(hours=13 * k),
            status="succeeded",
            evaluation_id=f"ev-{k:04d}",
            systems={
                name: SystemFigures(float(values[k]), rpe, 100, None)
                for name, values in ate.items()
            },
        )
        for k in range(count)
    ]


def _notes(runs: list[SummaryRun]) -> tuple[str, ...]:
    summary = SummaryInput(
        title="t", generated_at=MONDAY + dt.timedelta(days=7), selection="all", runs=runs
    )
    return build_summary_view(summary).stats_notes


def test_compare_runs_interval_and_verdict(rng: np.random.Generator) -> None:
    """A system 2 cm better over 20 runs is a_better; the interval holds the difference."""
    a = 0.05 + rng.normal(0.0, 0.005, 20)
    b = 0.07 + rng.normal(0.0, 0.005, 20)
    found = compare_runs(a, b, a="A", b="B", metric=ComparedMetric.ATE_RMSE)
    assert found.difference == pytest.approx(a.mean() - b.mean())
    assert found.ci95[0] <= found.difference <= found.ci95[1] < 0.0
    assert found.verdict.value == "a_better"
    assert found.n_common == 0
    # The unpaired interval's half-width is near 1.96 * sqrt(s_a²/n + s_b²/n) = 3.1 mm
    # (s = 5 mm, n = 20; block length 1 for uncorrelated runs).
    assert 0.002 < (found.ci95[1] - found.ci95[0]) / 2 < 0.0045
    same = compare_runs(a, a[::-1], a="A", b="A again", metric=ComparedMetric.ATE_RMSE)
    assert same.verdict.value == "within_noise"


def test_compare_runs_needs_eight_runs() -> None:
    """Fewer than 8 runs of a system is an input error naming it."""
    with pytest.raises(InputError, match="'B' has 5 finite per-run figures"):
        compare_runs([0.1] * 8, [0.1] * 5, a="A", b="B", metric=ComparedMetric.RPE_RMSE)


def test_summary_states_the_comparison_across_runs(rng: np.random.Generator) -> None:
    """The systems table's notes say, in words, which system is better across runs."""
    runs = _runs(
        {"AMCL": 0.05 + rng.normal(0.0, 0.004, 10), "SLAM": 0.09 + rng.normal(0.0, 0.004, 10)}
    )
    notes = _notes(runs)
    assert any(
        n.startswith("Across runs (mean RMSE per run): AMCL's ATE is lower than SLAM's")
        for n in notes
    )
    assert any("RPE differ by 0.0 cm" in n and "within the noise" in n for n in notes)


def test_summary_with_few_runs_says_why_it_does_not_compare(rng: np.random.Generator) -> None:
    """With fewer than 8 runs the summary says the systems are not compared across runs."""
    runs = _runs({"AMCL": rng.uniform(0.04, 0.06, 4), "SLAM": rng.uniform(0.08, 0.1, 4)})
    notes = _notes(runs)
    assert not any(n.startswith("Across runs") for n in notes)
    assert any("fewer than 8 evaluated runs are not compared" in n for n in notes)
