"""Block-bootstrap intervals, block lengths, effective sample sizes and tolerance verdicts."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from loceval.assessment.uncertainty import (
    BlockBootstrap,
    ToleranceOutcome,
    _autocorrelation,
    _fast_size,
    block_length,
    format_length_m,
    integrated_autocorrelation_time,
    interval_stats,
    n_effective,
    percentile_interval,
    tolerance_verdict,
)
from loceval.errors import InputError


def ar1(rng: np.random.Generator, n: int, phi: float, sigma: float, dims: int = 3) -> np.ndarray:
    """Return (n, dims) stationary AR(1) errors with per-axis standard deviation ``sigma``.

    ``x_t = φ x_{t-1} + w_t`` with ``w ~ N(0, σ²(1 - φ²))`` and ``x_0 ~ N(0, σ²)``: every
    x_t has variance σ², and the correlation time is ``(1 + φ) / (1 - φ)`` samples.
    """
    innovations = rng.normal(0.0, sigma * np.sqrt(1.0 - phi**2), (n, dims))
    first = rng.normal(0.0, sigma, dims)
    out, _ = lfilter([1.0], [1.0, -phi], innovations, axis=0, zi=(phi * first)[None, :])
    return out


@pytest.mark.slow
def test_coverage_of_the_rmse_interval(rng):
    """The block interval covers the true RMSE 93-97 % of the time; the i.i.d. one far less."""
    # 200 realisations of 3-D AR(1) position errors, φ = 0.95 (τ = 39 samples), 8,000
    # samples each (205 correlation times, e.g. 2.7 min at 50 Hz). The true RMSE of the
    # error norm is sqrt(E|x|²) = sqrt(3) σ.
    sigma, true_rmse = 0.03, np.sqrt(3.0) * 0.03
    block_hits = iid_hits = 0
    for seed in range(200):
        errors = np.linalg.norm(ar1(rng, 8000, 0.95, sigma), axis=1)
        lo, hi = interval_stats(errors, seed=seed).ci95["rmse"]
        block_hits += lo <= true_rmse <= hi
        # The i.i.d. bootstrap: blocks of one error (only the RMSE, to keep the test short).
        iid = BlockBootstrap.draw(errors.size, 1, resamples=500, seed=seed, cap_blocks=False)
        lo, hi = percentile_interval(np.sqrt(iid.means(errors**2)))
        iid_hits += lo <= true_rmse <= hi
    assert 0.93 <= block_hits / 200 <= 0.97
    # Measured with this seed: block 0.96 (median block length 98), i.i.d. 0.35: the
    # i.i.d. interval is narrower by about sqrt(τ_int of |x|²) ≈ 6.
    assert iid_hits / 200 < 0.6


def test_integrated_autocorrelation_time_of_ar1(rng):
    """τ of an AR(1) series is (1 + φ) / (1 - φ) within sampling error."""
    x = ar1(rng, 200_000, 0.9, 1.0, dims=1)[:, 0]
    # (1 + 0.9) / (1 - 0.9) = 19
    assert integrated_autocorrelation_time(x) == pytest.approx(19.0, rel=0.1)
    assert n_effective(x) == pytest.approx(200_000 / 19.0, rel=0.1)


def test_white_noise_needs_no_blocks(rng):
    """Independent errors get block length 1 and an effective size of about n."""
    x = rng.normal(size=20_000)
    assert block_length(x) == 1
    assert n_effective(x) == pytest.approx(20_000, rel=0.05)


def test_block_length_grows_with_correlation(rng):
    """The Politis-White block is longer for longer correlation, and about n^(1/3) scaled."""
    short = block_length(ar1(rng, 20_000, 0.5, 1.0, dims=1)[:, 0])
    long = block_length(ar1(rng, 20_000, 0.95, 1.0, dims=1)[:, 0])
    # For AR(1) with unit variance the optimum is (2 G² / (4/3 g²))^(1/3) n^(1/3) with
    # G = 2φ/(1-φ)² and g = (1+φ)/(1-φ): n = 20,000 gives 37.6 for φ = 0.5 and 225 for
    # φ = 0.95 (by hand); the lag-window estimate scatters around them (seen 33-37, 176-248).
    assert 25 <= short <= 50
    assert 150 <= long <= 320


def test_constant_series_has_zero_width():
    """A constant error has point intervals and no correlation to speak of."""
    stats = interval_stats(np.full(100, 0.02), thresholds_m=[0.01, 0.05])
    assert stats.ci95["rmse"] == pytest.approx((0.02, 0.02))
    assert stats.ci95["median"] == (0.02, 0.02)
    assert stats.within_ci95 == {0.01: (0.0, 0.0), 0.05: (1.0, 1.0)}
    assert stats.n_effective == 100.0


def test_intervals_contain_the_estimates_and_are_reproducible(rng):
    """Each interval holds the sample statistic; the same seed gives the same intervals."""
    errors = np.linalg.norm(ar1(rng, 5000, 0.9, 0.05), axis=1)
    stats = interval_stats(errors, thresholds_m=[0.05, 0.1])
    again = interval_stats(errors, thresholds_m=[0.05, 0.1])
    assert stats == again
    assert stats != interval_stats(errors, thresholds_m=[0.05, 0.1], seed=1)
    point = {
        "rmse": np.sqrt(np.mean(errors**2)),
        "mean": errors.mean(),
        "median": np.median(errors),
    }
    for key, value in point.items():
        lo, hi = stats.ci95[key]
        assert lo < value < hi
    for t, (lo, hi) in stats.within_ci95.items():
        assert lo < np.mean(errors <= t) < hi
    assert stats.n_effective < 5000 / 5
    assert set(stats.n_effective_by_statistic) == {"rmse", "mean", "median", "0.05", "0.1"}
    assert stats.to_dict()["within_ci95"] == {
        "0.05": list(stats.within_ci95[0.05]),
        "0.1": list(stats.within_ci95[0.1]),
    }


def test_median_interval_equals_percentiles_of_resampled_medians(rng):
    """The bisection gives exactly the percentiles of explicitly resampled lower medians."""
    x = np.linalg.norm(ar1(rng, 3001, 0.8, 1.0), axis=1)
    boot = BlockBootstrap.draw(x.size, 17, resamples=200, seed=3)
    # Independent computation: build each resample's values from its blocks.
    offsets = np.arange(boot.block)
    medians = []
    for starts in boot.starts:
        idx = ((starts[:, None] + offsets[None, :]) % x.size).ravel()[: x.size]
        medians.append(np.sort(x[idx])[(x.size + 1) // 2 - 1])
    expected = np.quantile(medians, [0.025, 0.975], method="inverted_cdf")
    assert boot.median_interval(x) == (expected[0], expected[1])


def test_block_sums_equal_explicit_resamples(rng):
    """Resample means from block sums equal the means of explicitly built resamples."""
    x = rng.normal(size=(2, 103))
    boot = BlockBootstrap.draw(103, 10, resamples=100, seed=5)
    offsets = np.arange(10)
    idx = ((boot.starts[:, :, None] + offsets) % 103).reshape(100, -1)[:, :103]
    np.testing.assert_allclose(boot.means(x), x[:, idx].mean(axis=2), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(boot.means(x[0]), x[0][idx].mean(axis=1), rtol=1e-9, atol=1e-15)


def test_bad_inputs_are_rejected():
    """Too few or non-finite errors and too few resamples raise InputError."""
    with pytest.raises(InputError, match="at least 8 values"):
        interval_stats(np.ones(5))
    with pytest.raises(InputError, match="NaN or inf"):
        interval_stats(np.array([1.0] * 9 + [np.nan]))
    with pytest.raises(InputError, match="at least 100") as info:
        interval_stats(np.ones(50), resamples=10)
    assert info.value.option == "resamples"


class TestToleranceVerdict:
    """PASS, FAIL or UNDECIDED from the interval of the share within the tolerance."""

    def test_clear_pass_and_fail(self, rng):
        """A share far above the requirement passes; far below fails."""
        errors = np.abs(ar1(rng, 4000, 0.9, 0.02, dims=1)[:, 0])
        # |N(0, 0.02)| ≤ 0.05 for 98.8 % of poses (2.5 sigma) and ≤ 0.01 for 38 %.
        passed = tolerance_verdict(errors, distance_m=0.05, required_share=0.9)
        assert passed.outcome is ToleranceOutcome.PASS
        assert passed.summary.startswith("PASS: 98.")
        failed = tolerance_verdict(errors, distance_m=0.01, required_share=0.9)
        assert failed.outcome is ToleranceOutcome.FAIL
        assert failed.ci95[1] < 0.9

    def test_straddling_interval_is_undecided(self, rng):
        """A requirement inside the share's interval gives UNDECIDED and says why."""
        errors = np.abs(ar1(rng, 4000, 0.95, 0.02, dims=1)[:, 0])
        share = float(np.mean(errors <= 0.03))
        verdict = tolerance_verdict(errors, distance_m=0.03, required_share=share)
        assert verdict.outcome is ToleranceOutcome.UNDECIDED
        assert verdict.ci95[0] < share < verdict.ci95[1]
        assert "straddles the requirement" in verdict.summary
        assert verdict.to_dict()["outcome"] == "undecided"

    def test_reuses_given_intervals(self, rng):
        """Intervals computed beforehand for the distance are used as they are."""
        errors = np.abs(rng.normal(0, 0.02, 500))
        stats = interval_stats(errors, thresholds_m=[0.05], seed=9)
        verdict = tolerance_verdict(errors, distance_m=0.05, required_share=0.5, intervals=stats)
        assert verdict.ci95 == stats.within_ci95[0.05]

    @pytest.mark.parametrize(
        ("distance", "share", "match"),
        [(0.0, 0.9, "positive metres"), (0.1, 1.5, r"\(0, 100\] percent")],
    )
    def test_bad_tolerance(self, distance, share, match):
        """A non-positive distance or a share outside (0, 1] names the tolerance option."""
        with pytest.raises(InputError, match=match) as info:
            tolerance_verdict(np.ones(20), distance_m=distance, required_share=share)
        assert info.value.option == "tolerance"


def test_format_length():
    """Lengths below a metre read in centimetres."""
    assert format_length_m(0.062) == "6.2 cm"
    assert format_length_m(1.5) == "1.50 m"


@pytest.mark.parametrize("n", [8, 9, 97, 1_000, 4_099, 50_000])
def test_autocorrelation_equals_its_definition(rng, n):
    """The FFT autocorrelation (on a 2-3-5 smooth length) is the direct sum, every lag.

    ρ_k = Σ_{t<n-k} (x_t - x̄)(x_{t+k} - x̄) / Σ_t (x_t - x̄)², computed here with
    ``np.correlate`` (no FFT): any circular overlap from too short a length would show.
    """
    x = ar1(rng, n, 0.7, 1.0, dims=1)[:, 0]
    c = x - x.mean()
    direct = np.correlate(c, c, mode="full")[n - 1 :] / np.dot(c, c)
    np.testing.assert_allclose(_autocorrelation(x), direct, rtol=0, atol=1e-12)


def test_fast_fft_lengths_are_the_smallest_2_3_5_smooth_ones():
    """Each length is 2**a 3**b 5**c, at least the one asked for, and none smaller is."""

    def smooth(k: int) -> bool:
        for p in (2, 3, 5):
            while k % p == 0:
                k //= p
        return k == 1

    for least in [*range(1, 2_000), 99_999, 131_073, 1_000_001]:
        size = _fast_size(least)
        assert size >= least
        assert smooth(size)
        assert not any(smooth(k) for k in range(least, size))
