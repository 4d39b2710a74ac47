"""The ground truth's own error: RMSE correction and the adequacy check."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.assessment.reference_error import check_reference_error, reference_mean_square_m2
from loceval.errors import InputError


def test_correction_recovers_the_system_rmse(rng):
    """Measured errors = system + reference noise: the corrected RMSE is the system's."""
    n = 200_000
    system = rng.normal(0.0, 0.05, (n, 3))
    reference = rng.normal(0.0, 0.03, (n, 3))
    measured = np.sqrt(np.mean(np.sum((system + reference) ** 2, axis=1)))
    check = check_reference_error(measured, reference_sigma_m=0.03)
    # System RMSE sqrt(3) * 0.05 = 0.0866 m; measured sqrt(3 (0.05² + 0.03²)) = 0.1010 m.
    assert check.corrected_rmse_m == pytest.approx(np.sqrt(3) * 0.05, rel=0.01)
    assert check.reference_rms_m == pytest.approx(np.sqrt(3) * 0.03)
    # 5.2 cm reference error > 8.7 cm / 3: not adequate.
    assert not check.adequate
    assert "more than a third of the system's own RMSE" in check.summary


def test_reference_robot_evaluating_a_5_cm_system():
    """A 6.7 cm reference cannot judge a 5 cm system (the issue's example)."""
    measured = float(np.hypot(0.05, 0.067))  # 8.36 cm
    check = check_reference_error(measured, reference_sigma_m=0.067, dof=1)
    assert check.corrected_rmse_m == pytest.approx(0.05)
    assert not check.adequate
    assert check.summary == (
        "The ground truth's own error (6.7 cm RMS) is more than a third of the system's own "
        "RMSE (5.0 cm), so it cannot tell the system's error from its own: evaluate against "
        "a more accurate reference."
    )


def test_optitrack_is_adequate():
    """OptiTrack's 0.2 mm changes a 19.4 cm RMSE by nothing that shows and is adequate."""
    check = check_reference_error(0.194, reference_sigma_m=0.0002, tolerance_m=0.10)
    assert check.corrected_rmse_m == pytest.approx(0.194, abs=1e-6)
    assert check.adequate
    assert check.summary == ""
    assert check.to_dict()["adequate"] is True


def test_tolerance_is_the_limit_when_tighter():
    """Against a 3 cm tolerance a 1.5 cm reference is not adequate even for a 20 cm system."""
    check = check_reference_error(0.20, reference_sigma_m=0.015 / np.sqrt(3), tolerance_m=0.03)
    assert check.limit_m == 0.03
    assert "third of the tolerance (3.0 cm)" in check.summary


def test_per_pose_covariance_and_rpe():
    """Covariances give the mean trace; an RPE error carries the reference twice."""
    cov = np.broadcast_to(np.diag([1e-4, 4e-4, 9e-4]), (10, 3, 3))
    assert reference_mean_square_m2(reference_cov=cov) == pytest.approx(14e-4)
    assert reference_mean_square_m2(reference_cov=cov, dof=2) == pytest.approx(5e-4)
    check = check_reference_error(0.1, reference_cov=cov, poses_per_error=2)
    assert check.reference_rms_m == pytest.approx(np.sqrt(28e-4))
    assert check.corrected_rmse_m == pytest.approx(np.sqrt(0.01 - 28e-4))


def test_reference_worse_than_the_measurement_clips_to_zero():
    """A reference error above the measured RMSE leaves a corrected RMSE of 0."""
    check = check_reference_error(0.01, reference_sigma_m=0.05)
    assert check.corrected_rmse_m == 0.0
    assert not check.adequate


@pytest.mark.parametrize(
    ("kwargs", "match", "option"),
    [
        ({}, "either as one standard deviation", "reference_sigma_m"),
        ({"reference_sigma_m": -1.0}, "non-negative number of metres", "reference_sigma_m"),
        ({"reference_sigma_m": 0.1, "dof": 4}, "must be 1, 2 or 3", None),
        ({"reference_cov": np.zeros((3, 2, 2))}, r"shape \(N, 3, 3\)", None),
        ({"reference_cov": np.full((3, 3, 3), np.nan)}, "NaN or inf", None),
        ({"reference_sigma_m": 0.1, "poses_per_error": 3}, "1 \\(ATE\\) or 2", None),
        ({"reference_sigma_m": 0.1, "tolerance_m": 0.0}, "positive metres", "tolerance"),
    ],
)
def test_bad_inputs(kwargs, match, option):
    """Missing, negative or misshapen reference errors raise with the option's key."""
    with pytest.raises(InputError, match=match) as info:
        check_reference_error(0.1, **kwargs)
    assert info.value.option == option


def test_bad_rmse():
    """A negative RMSE is a bad input."""
    with pytest.raises(InputError, match="non-negative number of metres"):
        check_reference_error(-0.1, reference_sigma_m=0.01)
