"""Trials of one system: figures over trials, their intervals, failed trials, systems compared."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from loceval.assessment.trial_comparison import _u_null_cdf, compare_systems
from loceval.assessment.trials import median_interval, summarise_trials
from loceval.errors import AssociationError, InputError
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.trajectory import Trajectory
from tests.factories import make_trajectory, perturb

NO_CI = EvaluationConfig(no_ci=True)


def test_figures_over_five_trials():
    """Median, mean, sample std, quartiles and the t-interval of the mean, as by hand."""
    m = summarise_trials([0.05, 0.01, 0.04, 0.02, 0.03], metric="ate_rmse", unit="m")
    assert (m.median, m.mean, m.min, m.max) == pytest.approx((0.03, 0.03, 0.01, 0.05))
    assert m.std == pytest.approx(math.sqrt(2.5) * 0.01)
    assert (m.q1, m.q3, m.iqr) == pytest.approx((0.02, 0.04, 0.02))
    half = stats.t.ppf(0.975, 4) * math.sqrt(2.5) * 0.01 / math.sqrt(5)
    assert m.interval is not None
    assert (m.interval.low, m.interval.high) == pytest.approx((0.03 - half, 0.03 + half))
    assert m.interval.level == 0.95
    assert "Student t" in m.interval.method
    assert m.median_interval is None  # 5 trials: min..max covers only 93.75 %
    assert m.note is None
    assert m.to_dict()["values"] == [0.05, 0.01, 0.04, 0.02, 0.03]


@pytest.mark.parametrize("n", [1, 2])
def test_too_few_trials_have_no_interval(n):
    """With fewer than 3 trials the figures come without an interval, and the note says why."""
    m = summarise_trials([0.02, 0.03][:n], metric="ate_rmse", unit="m")
    assert m.interval is None
    assert m.median_interval is None
    assert m.note is not None
    assert m.note.startswith("Too few trials for an interval")
    assert m.std == (0.0 if n == 1 else pytest.approx(np.std([0.02, 0.03], ddof=1)))


def test_median_interval_order_statistics():
    """6 trials: min to max, coverage 1 - 2/64; 9 trials: the 2nd to the 8th value."""
    six = median_interval([6.0, 1, 5, 2, 4, 3])
    assert six is not None
    assert (six.low, six.high, six.level) == pytest.approx((1.0, 6.0, 1 - 2 / 64))
    nine = median_interval(np.arange(9.0))
    assert nine is not None
    assert (nine.low, nine.high) == (1.0, 7.0)
    assert nine.level == pytest.approx(1 - 2 * stats.binom.cdf(1, 9, 0.5))


def test_nan_is_refused():
    """A trial value that is not finite is an input error, not a silent NaN."""
    with pytest.raises(InputError, match="finite value per trial"):
        summarise_trials([0.1, float("nan")], metric="ate_rmse", unit="m")


def test_interval_coverage_over_seeds():
    """Over 2000 seeds the t-interval of 5 trials covers the true mean ~95 % of the time, the
    order-statistic interval of 9 trials covers the true median at least its stated level."""
    covered_mean = covered_median = 0
    level = None
    seeds = 2000
    for seed in range(seeds):
        draws = np.random.default_rng(seed).normal(0.05, 0.01, 9)
        m5 = summarise_trials(draws[:5], metric="ate_rmse", unit="m")
        assert m5.interval is not None
        covered_mean += m5.interval.low <= 0.05 <= m5.interval.high
        m9 = summarise_trials(draws, metric="ate_rmse", unit="m")
        assert m9.median_interval is not None
        level = m9.median_interval.level
        covered_median += m9.median_interval.low <= 0.05 <= m9.median_interval.high
    assert 0.935 <= covered_mean / seeds <= 0.965
    assert level is not None
    assert covered_median / seeds >= level - 0.015


def test_mann_whitney_null_distribution():
    """The counted null distribution of U for 5 and 5: P(U <= 2) = 4/252, symmetric, sums to 1."""
    cdf = _u_null_cdf(5, 5)
    assert cdf[-1] == pytest.approx(1.0)
    assert cdf[0] == pytest.approx(1 / 252)
    assert cdf[2] == pytest.approx(4 / 252)
    pmf = np.diff(np.concatenate([[0.0], cdf]))
    np.testing.assert_allclose(pmf, pmf[::-1])


def test_systems_compared_over_trials():
    """Separated systems: a_better, Hodges-Lehmann shift, Moses interval [D_(3), D_(23)]."""
    a = np.array([0.020, 0.022, 0.019, 0.024, 0.021])
    b = np.array([0.040, 0.043, 0.038, 0.045, 0.041])
    found = compare_systems(a, b, a="orb", b="vins", metric="ate_rmse", unit="m")
    diffs = np.sort((a[:, None] - b[None, :]).ravel())
    assert found.difference == pytest.approx(float(np.median(diffs)))
    assert found.interval == pytest.approx((diffs[2], diffs[22]))
    assert found.confidence == pytest.approx(1 - 2 * 4 / 252)
    assert found.p_value == pytest.approx(2 / 252)
    assert found.verdict == "a_better"
    assert found.summary.startswith(
        "orb's ATE RMSE is lower than vins's by 2.0 cm over 5 against 5"
    )
    swapped = compare_systems(b, a, a="vins", b="orb", metric="ate_rmse", unit="m")
    assert swapped.verdict == "b_better"


def test_systems_alike_are_within_noise(rng):
    """Trials drawn from one distribution: the interval holds 0."""
    a, b = rng.normal(0.05, 0.005, 8), rng.normal(0.05, 0.005, 8)
    found = compare_systems(a, b, a="A", b="B", metric="ate_rmse", unit="m")
    assert found.verdict == "within_noise"
    assert found.interval is not None
    assert found.interval[0] < 0.0 < found.interval[1]


def test_too_few_trials_to_compare():
    """3 against 4 trials: 35 rankings, no 95 % interval exists: too_few_trials."""
    found = compare_systems([1.0, 2, 3], [4.0, 5, 6, 7], a="A", b="B", metric="ate_rmse", unit="m")
    assert found.verdict == "too_few_trials"
    assert found.interval is None
    assert "too few trials" in found.summary


def _trials(rng, ref, sigmas, system):
    return [
        replace(perturb(ref, rng, sigma_m=s, sigma_rad=0.002), name=f"{system}-{k + 1}")
        for k, s in enumerate(sigmas)
    ]


def test_evaluate_groups_trials_with_known_spread(rng):
    """Per-trial noise sigma_k gives ATE RMSE ~ sqrt(3) sigma_k: the system's figures follow."""
    ref = make_trajectory(rng, n=1500)
    sig_a = np.array([0.010, 0.012, 0.014, 0.016, 0.018])
    sig_b = np.array([0.030, 0.032, 0.034, 0.036, 0.038])
    estimates = _trials(rng, ref, sig_a, "A") + _trials(rng, ref, sig_b, "B")
    result = evaluate(ref, estimates, NO_CI, systems=["A"] * 5 + ["B"] * 5)
    a, b = result.systems
    assert (a.name, b.name) == ("A", "B")
    assert a.trials == tuple(f"A-{k}" for k in range(1, 6))
    ate = a.metrics["ate_rmse"]
    np.testing.assert_allclose(ate.values, math.sqrt(3) * sig_a, rtol=0.06)
    assert ate.median == pytest.approx(math.sqrt(3) * 0.014, rel=0.06)
    assert ate.std == pytest.approx(math.sqrt(3) * np.std(sig_a, ddof=1), rel=0.25)
    assert ate.interval is not None
    assert ate.interval.low < ate.mean < ate.interval.high
    assert set(a.metrics) == {"ate_rmse", "rpe_rmse", "ate_rot_rmse", "rpe_rot_rmse"}
    by = {(c.metric, c.a, c.b): c for c in result.system_comparisons}
    assert by["ate_rmse", "A", "B"].verdict == "a_better"
    assert by["rpe_rmse", "A", "B"].verdict == "a_better"
    assert not result.comparisons  # trials are compared as systems, not pairwise
    document = result.to_dict()
    assert [e["system"] for e in document["estimates"]] == ["A"] * 5 + ["B"] * 5
    assert document["systems"][0]["metrics"]["ate_rmse"]["n"] == 5


def test_failed_trials_are_counted_and_the_others_go_on(rng):
    """A trial outside the run in time and one that lost tracking are failed, named, counted."""
    ref = make_trajectory(rng, n=1000)
    good = _trials(rng, ref, [0.01, 0.012, 0.011], "A")
    lost = Trajectory(
        ref.stamps_ns[:200], good[0].positions_xyz[:200], good[0].quat_xyzw[:200], name="A-4"
    )
    later = replace(
        good[1], stamps_ns=good[1].stamps_ns + 10**12, name="A-5"
    )  # 1000 s after the run
    result = evaluate(ref, [*good, lost, later], NO_CI, systems=["A"] * 5)
    (system,) = result.systems
    assert system.trials == ("A-1", "A-2", "A-3")
    failed = {f.name: f for f in system.failed}
    assert set(failed) == {"A-4", "A-5"}
    assert failed["A-4"].code == "trial.tracking_lost"
    assert "tracked 20%" in failed["A-4"].reason
    assert failed["A-5"].code == AssociationError.code
    assert system.metrics["ate_rmse"].n == 3
    assert [e.name for e in result.estimates] == ["A-1", "A-2", "A-3", "A-4"]  # shown, not counted
    block = result.to_dict()["systems"][0]
    assert (block["n_trials"], block["n_failed"]) == (3, 2)


def test_an_estimate_of_no_system_still_fails_the_evaluation(rng):
    """Only trials are allowed to fail: a plain estimate outside the run raises as before."""
    ref = make_trajectory(rng, n=300)
    later = replace(perturb(ref, rng), stamps_ns=ref.stamps_ns + 10**12, name="late")
    with pytest.raises(AssociationError):
        evaluate(ref, [later], NO_CI)


def test_every_trial_failed(rng):
    """When no trial can be evaluated the evaluation says so, naming each."""
    ref = make_trajectory(rng, n=300)
    later = replace(perturb(ref, rng), stamps_ns=ref.stamps_ns + 10**12, name="late")
    with pytest.raises(InputError, match=r"Every trial failed.*late"):
        evaluate(ref, [later], NO_CI, systems=["A"])
