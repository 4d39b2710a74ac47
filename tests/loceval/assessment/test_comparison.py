"""Paired block-bootstrap comparisons of two systems on the same reference."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.assessment.comparison import (
    ComparedMetric,
    ComparisonVerdict,
    compare_errors,
    compare_series,
)
from loceval.errors import InputError, MetricError
from loceval.metrics.pose_errors import ErrorSeries
from tests.loceval.assessment.test_uncertainty import ar1

T0 = 1_700_000_000 * 10**9
DT = 20_000_000  # 50 Hz


def series(errors: np.ndarray, start: int = 0) -> ErrorSeries:
    """Return ATE norms with 50 Hz stamps starting at pose ``start``."""
    stamps = T0 + (start + np.arange(errors.shape[0], dtype=np.int64)) * DT
    return ErrorSeries(np.linalg.norm(errors, axis=1), stamps, "m")


def test_clearly_better_system(rng):
    """A system with 2 cm errors beats one with 6 cm errors: a_better, and the sentence."""
    shared = ar1(rng, 6000, 0.95, 0.02)  # the hard stretches both systems share
    a = series(shared)
    b = series(3.0 * shared + ar1(rng, 6000, 0.95, 0.01))
    (result,) = compare_series([("RTAB-Map", a), ("ISAAC", b)], metric=ComparedMetric.ATE_RMSE)
    assert result.verdict is ComparisonVerdict.A_BETTER
    expected = np.sqrt(np.mean(a.values**2)) - np.sqrt(np.mean(b.values**2))
    assert result.difference == pytest.approx(expected, rel=1e-12)
    lo, hi = result.ci95
    assert lo < result.difference < hi < 0.0
    assert result.summary.startswith("RTAB-Map's ATE is lower than ISAAC's: difference ")
    assert result.summary.endswith(" cm.")
    assert result.to_dict() == {
        "a": "RTAB-Map",
        "b": "ISAAC",
        "metric": "ate_rmse",
        "difference": result.difference,
        "ci95": [lo, hi],
        "verdict": "a_better",
    }
    swapped = compare_series([("ISAAC", b), ("RTAB-Map", a)], metric=ComparedMetric.ATE_RMSE)[0]
    assert swapped.verdict is ComparisonVerdict.B_BETTER
    assert swapped.summary.startswith("RTAB-Map's ATE is lower than ISAAC's")


def test_identical_noise_is_within_noise(rng):
    """Two systems with errors of the same distribution differ within the noise."""
    a = series(ar1(rng, 6000, 0.95, 0.03))
    b = series(ar1(rng, 6000, 0.95, 0.03))
    result = compare_errors(
        a.stamps_ns, a.values, b.stamps_ns, b.values, a="A", b="B",
        metric=ComparedMetric.RPE_RMSE,
    )  # fmt: skip
    assert result.verdict is ComparisonVerdict.WITHIN_NOISE
    assert result.ci95[0] < 0.0 < result.ci95[1]
    assert result.summary.startswith("A's and B's RPE differ by ")
    assert result.summary.endswith("the difference is within the noise.")


def test_pairing_narrows_the_interval(rng):
    """Shared error stretches cancel: the paired interval is narrower than unpaired resamples."""
    shared = ar1(rng, 6000, 0.98, 0.05)
    a = series(shared + ar1(rng, 6000, 0.5, 0.005))
    b = series(shared + ar1(rng, 6000, 0.5, 0.006))
    paired = compare_series([("A", a), ("B", b)], metric=ComparedMetric.ATE_RMSE)[0]
    # Unpaired: shift B's stamps by half the run so the resamples of A and B are unrelated
    # blocks; same data, same seed.
    half = 3000
    shifted_b = np.roll(b.values, half)
    unpaired = compare_errors(
        a.stamps_ns, a.values, b.stamps_ns, shifted_b, a="A", b="B",
        metric=ComparedMetric.ATE_RMSE,
    )  # fmt: skip
    assert paired.ci95[1] - paired.ci95[0] < 0.5 * (unpaired.ci95[1] - unpaired.ci95[0])


def test_only_common_stamps_count(rng):
    """Stamps only one system matched are left out of both RMSEs."""
    errors = ar1(rng, 1000, 0.9, 0.02)
    a = series(errors)
    b = series(errors[200:], start=200)
    result = compare_series([("A", a), ("B", b)], metric=ComparedMetric.ATE_RMSE)[0]
    assert result.n_common == 800
    assert result.difference == 0.0
    assert result.ci95 == (0.0, 0.0)
    assert result.verdict is ComparisonVerdict.WITHIN_NOISE


def test_all_pairs_in_order(rng):
    """Three systems give (A, B), (A, C), (B, C)."""
    named = [(n, series(ar1(rng, 200, 0.5, 0.02))) for n in "ABC"]
    pairs = [(c.a, c.b) for c in compare_series(named, metric=ComparedMetric.ATE_RMSE)]
    assert pairs == [("A", "B"), ("A", "C"), ("B", "C")]


def test_units_in_sentences(rng):
    """Degrees and metres above 1 m read in their own units."""
    a = ar1(rng, 500, 0.5, 1.0, dims=1)[:, 0] ** 2
    stamps = T0 + np.arange(500, dtype=np.int64) * DT
    deg = compare_errors(
        stamps, a, stamps, 10 * a, a="A", b="B", metric=ComparedMetric.RPE_RMSE, unit="deg"
    )
    assert deg.summary.endswith("°.")
    metres = compare_errors(stamps, a, stamps, 10 * a, a="A", b="B", metric=ComparedMetric.ATE_RMSE)
    assert metres.summary.endswith(" m.")


def test_bad_inputs(rng):
    """Few common stamps, repeated stamps, mismatched lengths and mixed units raise."""
    a = series(ar1(rng, 100, 0.5, 0.02))
    b = series(ar1(rng, 100, 0.5, 0.02), start=95)
    with pytest.raises(MetricError, match="share only 5 matched stamps"):
        compare_series([("A", a), ("B", b)], metric=ComparedMetric.ATE_RMSE)
    stamps = np.zeros(10, dtype=np.int64)
    with pytest.raises(InputError, match="repeats stamps"):
        compare_errors(stamps, np.ones(10), stamps, np.ones(10), a="A", b="B",
                       metric=ComparedMetric.ATE_RMSE)  # fmt: skip
    with pytest.raises(InputError, match="same length"):
        compare_errors(a.stamps_ns, a.values[:5], a.stamps_ns, a.values, a="A", b="B",
                       metric=ComparedMetric.ATE_RMSE)  # fmt: skip
    deg = ErrorSeries(a.values, a.stamps_ns, "deg")
    with pytest.raises(InputError, match="one unit") as info:
        compare_series([("A", a), ("B", deg)], metric=ComparedMetric.RPE_RMSE)
    assert info.value.option == "rpe_unit"
