"""Metrics: statistics, ATE, RPE, drift, CDF, thresholds, greatest errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.core.geometry import SimilarityTransform
from loceval.errors import MetricError
from loceval.metrics.pose_errors import (
    ErrorSeries,
    ErrorStats,
    RPEUnit,
    compute_ate,
    compute_drift,
    compute_rpe,
    drift_segment_lengths_m,
    greatest_errors,
    rpe_pairs,
    share_within,
)
from loceval.trajectory import Trajectory
from tests.factories import make_trajectory


def _series(values: list[float]) -> ErrorSeries:
    return ErrorSeries(np.asarray(values), np.arange(len(values), dtype=np.int64), "m")


def test_pathcompare_statistics() -> None:
    """rmse, mean, median, std, var, min, max, sse, n of a known series."""
    stats = _series([3.0, 4.0, 0.0, 5.0]).stats
    assert stats == ErrorStats(
        rmse=np.sqrt(50 / 4), mean=3.0, median=3.5, std=np.sqrt(3.5), var=3.5, min=0.0,
        max=5.0, sse=50.0, n=4,
    )  # fmt: skip
    assert stats.rmse**2 == pytest.approx(stats.mean**2 + stats.std**2)
    with pytest.raises(MetricError, match="No errors"):
        _series([]).stats  # noqa: B018


def test_cdf_and_share_within() -> None:
    """The CDF is the sorted errors with shares; thresholds count errors <= t."""
    series = _series([0.2, 0.05, 0.1, 0.15])
    values, shares = series.cdf()
    np.testing.assert_allclose(values, [0.05, 0.1, 0.15, 0.2])
    np.testing.assert_allclose(shares, [0.25, 0.5, 0.75, 1.0])
    assert share_within(series, [0.05, 0.1, 0.15]) == {0.05: 0.25, 0.1: 0.5, 0.15: 0.75}


def test_greatest_errors_are_sorted_with_time_and_place(truth: Trajectory) -> None:
    """The greatest errors come largest first with their stamp and reference position."""
    values = np.zeros(len(truth))
    values[[10, 200, 30]] = [0.5, 0.9, 0.7]
    series = ErrorSeries(values, truth.stamps_ns, "m")
    worst = greatest_errors(series, truth, count=3, separation_s=0.0)
    assert [w.index for w in worst] == [200, 30, 10]
    assert worst[0].t_s == pytest.approx(2.0)
    np.testing.assert_allclose(worst[0].position_xyz, truth.positions_xyz[200])


def test_greatest_errors_list_a_burst_once(truth: Trajectory) -> None:
    """Errors within 2 s of a greater listed one are its burst: the next listed is farther.

    5 s at 100 Hz: a burst of 0.5 m around pose 100 (1 s) with its peak 0.9 m at pose 105,
    a lone 0.7 m at pose 150 (0.45 s after the peak: the same burst) and 0.6 m at pose 400
    (2.95 s later). Listed: 105, then 400; no pose lies 2 s from both, so a third is not
    invented. Ranks #1, #2 have no gap in any output that numbers them.
    """
    values = np.zeros(len(truth))
    values[95:115] = 0.5
    values[[105, 150, 400]] = [0.9, 0.7, 0.6]
    worst = greatest_errors(ErrorSeries(values, truth.stamps_ns, "m"), truth, count=3)
    assert [w.index for w in worst] == [105, 400]
    assert [w.error for w in worst] == [0.9, 0.6]
    times = [w.t_s for w in worst]
    assert min(abs(a - b) for a in times for b in times if a != b) >= 2.0


def test_ate_is_zero_for_identical_and_exact_for_an_offset(truth: Trajectory) -> None:
    """ATE of a trajectory against itself is 0; a 0.1 m shift gives 0.1 m everywhere."""
    t_err, r_err = compute_ate(truth, truth)
    assert t_err.stats.max == 0.0
    assert r_err is not None
    assert r_err.stats.max < 1e-6
    shifted = truth.transformed(SimilarityTransform(np.eye(3), np.array([0.0, 0.1, 0.0])))
    np.testing.assert_allclose(compute_ate(truth, shifted)[0].values, 0.1)


def test_rpe_sees_a_constant_offset_as_zero(truth: Trajectory) -> None:
    """A rigidly moved estimate has zero relative error (RPE is frame-independent)."""
    moved = truth.transformed(
        SimilarityTransform(Rotation.from_euler("z", 1.0).as_matrix(), np.array([1.0, 2, 3]))
    )
    t_err, r_err = compute_rpe(truth, moved)
    assert t_err.stats.max < 1e-9
    assert r_err is not None
    assert r_err.stats.max < 1e-5
    assert len(t_err) == len(truth) - 1


def test_rpe_of_a_scaled_step() -> None:
    """Each step 10 % too long gives an RPE of 10 % of the step."""
    stamps = np.arange(5, dtype=np.int64)
    x = np.arange(5, dtype=float)
    ref = Trajectory(stamps, np.stack([x, 0 * x, 0 * x], 1), np.tile([0, 0, 0, 1.0], (5, 1)))
    est = Trajectory(stamps, np.stack([1.1 * x, 0 * x, 0 * x], 1), np.tile([0, 0, 0, 1.0], (5, 1)))
    t_err, _ = compute_rpe(ref, est, delta=2)
    np.testing.assert_allclose(t_err.values, [0.2, 0.2])
    pos_only, none = compute_rpe(ref.without_orientation(), est.without_orientation())
    assert none is None
    np.testing.assert_allclose(pos_only.values, 0.1)


def test_rpe_pairs_in_frames_metres_and_seconds() -> None:
    """Pairs step by delta frames, metres travelled or seconds; consecutive or all."""
    stamps = np.arange(11, dtype=np.int64) * 500_000_000
    x = np.arange(11, dtype=float)
    ref = Trajectory(stamps, np.stack([x, 0 * x, 0 * x], 1))
    i, j = rpe_pairs(ref, delta=3, unit=RPEUnit.FRAMES)
    np.testing.assert_array_equal(np.stack([i, j]), [[0, 3, 6], [3, 6, 9]])
    i, j = rpe_pairs(ref, delta=3, unit=RPEUnit.FRAMES, all_pairs=True)
    assert len(i) == 8
    i, j = rpe_pairs(ref, delta=2.5, unit=RPEUnit.METRES)
    np.testing.assert_array_equal(np.stack([i, j]), [[0, 3, 6], [3, 6, 9]])
    i, j = rpe_pairs(ref, delta=2.0, unit=RPEUnit.SECONDS, all_pairs=True)
    np.testing.assert_array_equal(j - i, 4)
    with pytest.raises(MetricError, match="whole number"):
        rpe_pairs(ref, delta=1.5, unit=RPEUnit.FRAMES)
    with pytest.raises(MetricError, match="positive"):
        rpe_pairs(ref, delta=0, unit=RPEUnit.SECONDS)
    with pytest.raises(MetricError, match="longer than the matched trajectory"):
        compute_rpe(ref, ref, delta=50)


def test_drift_of_a_scale_error() -> None:
    """A 2 % too long straight path drifts 2 % over every segment."""
    n = 2001
    stamps = np.arange(n, dtype=np.int64)
    x = np.linspace(0, 200, n)
    ref = Trajectory(stamps, np.stack([x, 0 * x, 0 * x], 1), np.tile([0, 0, 0, 1.0], (n, 1)))
    est = Trajectory(stamps, np.stack([1.02 * x, 0 * x, 0 * x], 1), ref.quat_xyzw)
    drift = compute_drift(ref, est)
    assert drift is not None
    np.testing.assert_allclose(drift.values, 2.0, rtol=1e-6)
    assert drift_segment_lengths_m(200.0)[0] == pytest.approx(20.0)
    assert drift_segment_lengths_m(3000.0) == tuple(float(v) for v in range(100, 801, 100))
    still = Trajectory(stamps[:3], np.zeros((3, 3)))
    assert compute_drift(still, still) is None


def test_metrics_need_matched_inputs(truth: Trajectory) -> None:
    """Unmatched lengths are a MetricError, not a silent broadcast."""
    with pytest.raises(MetricError, match="matched poses"):
        compute_ate(truth, truth.select(np.arange(10)))


@pytest.mark.parametrize(
    ("delta", "unit", "suggest"),
    [
        (1e-12, RPEUnit.SECONDS, "0.1"),
        (1e-300, RPEUnit.METRES, None),
        (0.05, RPEUnit.SECONDS, "0.1"),
    ],
)
@pytest.mark.parametrize("all_pairs", [False, True])
def test_rpe_delta_below_one_step_is_refused(
    delta: float, unit: RPEUnit, suggest: str | None, *, all_pairs: bool
) -> None:
    """A delta below the sampling interval (or step) is an error suggesting the least valid one."""
    rng = np.random.default_rng(7)
    ref = make_trajectory(rng, 100, dt_ns=100_000_000)
    with pytest.raises(MetricError, match=r"below the reference's median") as err:
        rpe_pairs(ref, delta=delta, unit=unit, all_pairs=all_pairs)
    assert err.value.option == "rpe_delta"
    assert err.value.suggest is not None
    if suggest is not None:
        assert err.value.suggest == suggest
    i, j = rpe_pairs(ref, delta=float(err.value.suggest), unit=unit, all_pairs=all_pairs)
    assert i.size
    assert (j > i).all()
    assert i.size <= len(ref) - 1
