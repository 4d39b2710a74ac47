"""Intervals, comparisons, NEES and the reference's own error, wired into the evaluation."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from loceval.evaluation import EvaluationConfig, Tolerance, evaluate
from loceval.registration.association import AssociationMethod
from loceval.trajectory import Trajectory
from tests.loceval.conftest import smooth_trajectory


def _noisy(
    rng: np.random.Generator,
    truth: Trajectory,
    name: str,
    sigma_m: float,
    *,
    cov_scale: float | None = None,
) -> Trajectory:
    """Return ``truth`` with AR(1) position noise of per-axis std ``sigma_m`` (and its covariance).

    The noise is autocorrelated (coefficient 0.9 per pose), as real errors are; ``cov_scale``
    attaches ``cov_scale * sigma_m² I`` as each pose's reported position covariance.
    """
    n = len(truth)
    white = rng.normal(0.0, sigma_m * np.sqrt(1 - 0.9**2), (n, 3))
    noise = np.empty((n, 3))
    noise[0] = rng.normal(0.0, sigma_m, 3)
    for k in range(1, n):  # test data generator, not a hot path
        noise[k] = 0.9 * noise[k - 1] + white[k]
    cov = None
    if cov_scale is not None:
        cov = np.zeros((n, 6, 6))
        cov[:, :3, :3] = cov_scale * sigma_m**2 * np.eye(3)
        cov[:, 3:, 3:] = 1e-4 * np.eye(3)
    return Trajectory(
        truth.stamps_ns,
        truth.positions_xyz + noise,
        truth.quat_xyzw,
        name=name,
        source=f"{name}.tum",
        cov6=cov,
    )


def _doc(result: Any) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    return out


def test_intervals_contain_the_point_values(rng: np.random.Generator) -> None:
    """Every STATS block gains ci95 around its rmse/mean/median and a plausible n_effective."""
    truth = smooth_trajectory(rng, n=2000)
    doc = _doc(evaluate(truth, [_noisy(rng, truth, "A", 0.02)]))
    est = doc["estimates"][0]
    for block in (est["ate"], est["rpe"]):
        for stats in (block["translation_m"], block["rotation_deg"]):
            assert set(stats["ci95"]) == {"rmse", "mean", "median"}
            for key, (lo, hi) in stats["ci95"].items():
                assert lo <= stats[key] <= hi, key
            assert 1.0 <= stats["n_effective"] <= stats["n"]
    ate = est["ate"]["translation_m"]
    # n_effective is that of the squared errors: AR(1) noise with coefficient 0.9 has squares
    # correlated with 0.81 per pose, tau = (1 + 0.81) / (1 - 0.81) = 9.5, so the 2000 poses
    # are worth about 210 independent errors (measured: 295, the windowed estimate of tau
    # over one run is noisy); the i.i.d. figure would be 2000.
    assert 100 < ate["n_effective"] < 450
    lo, hi = ate["ci95"]["rmse"]
    assert lo < 0.02 * np.sqrt(3) < hi  # the true RMSE of 3 axes of std 2 cm
    assert set(est["within_ci95"]) == set(est["within"])
    for key, (lo, hi) in est["within_ci95"].items():
        assert lo <= est["within"][key] <= hi


def test_no_ci_turns_intervals_and_comparisons_off(rng: np.random.Generator) -> None:
    """With no_ci every ci95, n_effective, within_ci95 and the comparisons are null."""
    truth = smooth_trajectory(rng, n=600)
    estimates = [_noisy(rng, truth, "A", 0.01), _noisy(rng, truth, "B", 0.03)]
    config = EvaluationConfig(no_ci=True, tolerance=Tolerance(0.05, 0.9))
    doc = _doc(evaluate(truth, estimates, config))
    assert doc["comparisons"] is None
    assert doc["options"]["no_ci"] is True
    for est in doc["estimates"]:
        for stats in (est["ate"]["translation_m"], est["rpe"]["rotation_deg"]):
            assert stats["ci95"] is None
            assert stats["n_effective"] is None
        assert est["within_ci95"] is None
        assert est["verdict"]["ci95"] is None
        assert est["verdict"]["outcome"] == ("pass" if est["verdict"]["passed"] else "fail")
        assert est["consistency"] is None


def test_reruns_give_identical_json(rng: np.random.Generator) -> None:
    """The bootstrap is seeded: the same inputs give the same intervals, to the last bit."""
    truth = smooth_trajectory(rng, n=800)
    estimates = [_noisy(rng, truth, "A", 0.01), _noisy(rng, truth, "B", 0.02)]
    first, second = (_doc(evaluate(truth, estimates)) for _ in range(2))
    first.pop("created_at")
    second.pop("created_at")
    assert first == second


def test_comparisons_find_the_better_system(rng: np.random.Generator) -> None:
    """A (1 cm noise) beats B (4 cm) on ATE; the pair is stated A before B in words."""
    truth = smooth_trajectory(rng, n=3000)
    estimates = [_noisy(rng, truth, "A", 0.01), _noisy(rng, truth, "B", 0.04)]
    result = evaluate(truth, estimates)
    doc = _doc(result)
    assert [(c["a"], c["b"], c["metric"]) for c in doc["comparisons"]] == [
        ("A", "B", "ate_rmse"),
        ("A", "B", "rpe_rmse"),
    ]
    ate = doc["comparisons"][0]
    rmse = {e["name"]: e["ate"]["translation_m"]["rmse"] for e in doc["estimates"]}
    assert ate["difference"] == pytest.approx(rmse["A"] - rmse["B"])  # same matched stamps
    assert ate["ci95"][0] <= ate["difference"] <= ate["ci95"][1] < 0.0
    assert ate["verdict"] == "a_better"
    assert result.comparisons is not None
    assert result.comparisons[0].summary.startswith("A's ATE is lower than B's: difference")
    swapped = _doc(evaluate(truth, estimates[::-1]))["comparisons"][0]
    assert swapped["verdict"] == "b_better"
    assert swapped["difference"] == pytest.approx(-ate["difference"])


def test_equal_systems_are_within_noise(rng: np.random.Generator) -> None:
    """Two systems with the same noise level differ only by noise: within_noise."""
    truth = smooth_trajectory(rng, n=3000)
    estimates = [_noisy(rng, truth, "A", 0.02), _noisy(rng, truth, "B", 0.02)]
    result = evaluate(truth, estimates)
    assert result.comparisons is not None
    ate = result.comparisons[0]
    assert ate.verdict.value == "within_noise"
    assert ate.ci95[0] < 0.0 < ate.ci95[1]
    assert "within the noise" in ate.summary


def test_tolerance_verdict_undecided_when_interval_straddles(rng: np.random.Generator) -> None:
    """A required share inside the share's interval gives undecided, passed false."""
    truth = smooth_trajectory(rng, n=2000)
    est = _noisy(rng, truth, "A", 0.02)
    probe = evaluate(truth, [est]).estimates[0].ate_translation.values
    distance = float(np.quantile(probe, 0.8))  # 80 % of the errors are within it
    doc = _doc(evaluate(truth, [est], EvaluationConfig(tolerance=Tolerance(distance, 0.8))))
    verdict = doc["estimates"][0]["verdict"]
    assert verdict["outcome"] == "undecided"
    assert verdict["passed"] is False
    assert verdict["ci95"][0] < 0.8 < verdict["ci95"][1]
    assert verdict["summary"].startswith("UNDECIDED: ")
    assert "straddles the requirement" in verdict["summary"]
    passing = _doc(evaluate(truth, [est], EvaluationConfig(tolerance=Tolerance(1.0, 0.9))))
    assert passing["estimates"][0]["verdict"]["outcome"] == "pass"
    assert passing["estimates"][0]["verdict"]["passed"] is True


@pytest.mark.parametrize(
    ("cov_scale", "verdict"),
    [(1.0, "consistent"), (4.0, "conservative"), (0.25, "overconfident")],
)
def test_consistency_of_reported_covariance(
    rng: np.random.Generator, cov_scale: float, verdict: str
) -> None:
    """Correct, doubled and halved sigma: consistent, conservative, overconfident."""
    truth = smooth_trajectory(rng, n=3000)
    est = _noisy(rng, truth, "A", 0.02, cov_scale=cov_scale).without_orientation()
    config = EvaluationConfig(no_ci=True)  # the NEES needs no bootstrap
    consistency = _doc(evaluate(truth, [est], config))["estimates"][0]["consistency"]
    assert consistency["verdict"] == verdict
    assert consistency["nees_position"]["dof"] == 3
    # The SE(3) alignment absorbs a little of the error, so the mean is near 3 / cov_scale.
    assert consistency["nees_position"]["mean"] == pytest.approx(3.0 / cov_scale, rel=0.25)


def test_reference_sigma_is_taken_out_and_judged(rng: np.random.Generator) -> None:
    """The reference's own error shrinks the RMSE and, when large, is reported as inadequate."""
    truth = smooth_trajectory(rng, n=1000)
    est = _noisy(rng, truth, "A", 0.02)
    small = _doc(evaluate(truth, [est], EvaluationConfig(reference_sigma_m=0.0002)))
    check = small["estimates"][0]["reference_error"]["ate"]
    rmse = small["estimates"][0]["ate"]["translation_m"]["rmse"]
    assert check["corrected_rmse"] == pytest.approx(np.sqrt(rmse**2 - 3 * 0.0002**2))
    assert check["adequate"] is True
    assert small["estimates"][0]["reference_error"]["rpe"]["reference_rms"] == pytest.approx(
        np.sqrt(2 * 3) * 0.0002  # an RPE error holds two reference poses
    )
    large = evaluate(truth, [est], EvaluationConfig(reference_sigma_m=0.02))
    assert any("ground truth's own error" in w for w in large.estimates[0].warnings)
    assert _doc(large)["estimates"][0]["reference_error"]["ate"]["adequate"] is False
    plain = _doc(evaluate(truth, [est], EvaluationConfig(no_ci=True)))
    assert plain["estimates"][0]["reference_error"] is None


@pytest.mark.public_data
def test_nav2_amcl_consistency_matches_an_independent_computation(public_data: Path) -> None:
    """AMCL's /amcl_pose against tf map->base_link: planar NEES (dof 2) as computed by hand."""
    from loceval.readers import read_trajectory

    bag = public_data / "nav2_turtlebot.mcap"
    reference = read_trajectory(f"{bag}@tf:map:base_link")
    amcl = read_trajectory(f"{bag}@/amcl_pose", name="AMCL")
    assert amcl.cov6 is not None
    config = EvaluationConfig(association=AssociationMethod.NEAREST, max_dt_s=0.05)
    result = evaluate(reference, [amcl], config)
    block = _doc(result)["estimates"][0]["consistency"]
    assert block["nees_position"]["dof"] == 2
    assert block["nees_rotation"]["dof"] == 1
    # Independent: rotate each matched pose's x-y covariance by the alignment's rotation
    # and solve e^T S^-1 e with numpy for the aligned x-y error.
    e = result.estimates[0]
    rot = e.alignment.transform.rotation
    cov = e.association.estimate.cov6
    assert cov is not None
    cov_aligned = rot @ cov[:, :3, :3] @ rot.T
    err = (e.aligned.positions_xyz - e.reference.positions_xyz)[:, :2]
    solved = np.linalg.solve(cov_aligned[:, :2, :2], err[..., None])[..., 0]
    nees = np.einsum("ni,ni->n", err, solved)
    assert block["nees_position"]["mean"] == pytest.approx(float(nees.mean()), rel=1e-9)
    assert block["verdict"] in {"consistent", "conservative", "overconfident"}


def test_long_runs_get_the_same_intervals_in_threads(rng: np.random.Generator) -> None:
    """Series of 20,000+ errors are bootstrapped in threads, with the sequential result."""
    from loceval.assessment.uncertainty import interval_stats

    truth = smooth_trajectory(rng, n=20_000)
    result = evaluate(truth, [_noisy(rng, truth, "A", 0.02)])
    e = result.estimates[0]
    assert e.assessment is not None
    for name in ("ate_rotation", "rpe_translation"):
        series = getattr(e, name)
        assert e.assessment.intervals[name].ci95 == interval_stats(series.values).ci95


def test_reference_covariance_gives_its_error(rng: np.random.Generator) -> None:
    """A reference that reports covariances has its error taken out without a sigma."""
    truth = smooth_trajectory(rng, n=1000)
    cov = np.zeros((len(truth), 6, 6))
    cov[:, :3, :3] = 0.001**2 * np.eye(3)  # 1 mm per axis
    reference = Trajectory(truth.stamps_ns, truth.positions_xyz, truth.quat_xyzw, cov6=cov)
    doc = _doc(evaluate(reference, [_noisy(rng, truth, "A", 0.02)], EvaluationConfig(no_ci=True)))
    check = doc["estimates"][0]["reference_error"]["ate"]
    assert check["reference_rms"] == pytest.approx(np.sqrt(3) * 0.001)  # sqrt(trace) of 3 axes
    assert check["corrected_rmse"] < check["rmse"]
