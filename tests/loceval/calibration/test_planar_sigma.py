"""The device rotation about a planar run's only axis: its sigma holds on unseen planar runs.

Recordings of :mod:`tests.planar_factory`: a ground robot drives loops of several shapes,
speed profiles, noise, rates and lengths; its estimate drifts in heading. The method (the
sigma of :func:`loceval.calibration.handeye._travel_axis_sigma`, and the device offset
estimated on the clock the data show) was checked on ``TUNING`` with seeds 0 to 9; the
families and seeds here (``HELD_OUT``, seeds 100 to 107) were run only once it was fixed.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.calibration.offsets import check_offsets
from loceval.core.geometry import SimilarityTransform
from loceval.trajectory import Trajectory
from tests.clock_factory import ClockTruth, restamp
from tests.planar_factory import HELD_OUT, TUNING, make_planar_recording

SEEDS = range(100, 108)


def _rz_error_and_sigma(
    reference: Trajectory, estimate: Trajectory, device: SimilarityTransform
) -> tuple[float, float]:
    """The device rotation's error about z (deg) and its sigma, from the evaluation's check."""
    check = check_offsets(reference, estimate, time_offset_s=None, auto_device=True, max_gap_s=0.1)
    found = check.device
    assert found is not None
    assert "rz" not in found.unobservable
    truth = Rotation.from_matrix(np.array(device.rotation))
    error = (Rotation.from_quat(np.array(found.rotation_xyzw)) * truth.inv()).as_rotvec()
    sigma = found.sigma_rotation_deg[2]
    assert sigma is not None
    return float(np.degrees(error[2])), sigma


@pytest.mark.slow
def test_rotation_about_the_axis_within_3_sigma_on_held_out_runs() -> None:
    """40 held-out planar runs (5 families x 8 seeds): rz within 3 sigma in at least 95 %.

    Measured when written: all 40 within 3 sigma, the largest at 1.69 sigma, their RMS 0.71
    sigma (0.32 to 0.81 per family; on seeds 100 to 109, 50 runs, all within as well).
    """
    z, sigmas = [], []
    for family in HELD_OUT:
        for seed in SEEDS:
            rec = make_planar_recording(np.random.default_rng(seed), family)
            error, sigma = _rz_error_and_sigma(rec.reference, rec.estimate, rec.device)
            z.append(error / sigma)
            sigmas.append(sigma)
    within = np.mean(np.abs(z) <= 3.0)
    assert len(z) >= 40
    assert within >= 0.95, np.round(z, 2)
    # Honest, not blown up: a fraction of a degree but on the 90 s runs whose heading
    # drifts by 30 deg a minute (1.07 deg there at most); measured median 0.052 deg.
    assert np.median(sigmas) < 0.1, np.round(sigmas, 3)
    assert max(sigmas) < 1.5, np.round(sigmas, 3)


def test_a_drifting_clock_does_not_bend_the_rotation() -> None:
    """A clock 100 ppm fast, not applied: the device rotation is still found within 3 sigma.

    Before the device offset was estimated on the clock the data show, a clock off by 45 ms
    bent it by up to 2.7 sigma on these runs.
    """
    family = TUNING[1]
    for seed in range(2):
        rec = make_planar_recording(np.random.default_rng(seed), family)
        for clock in (ClockTruth(rate_ppm=100.0), ClockTruth(offset_s=-0.045)):
            estimate = restamp(rec.estimate, clock)
            check = check_offsets(
                rec.reference, estimate, time_offset_s=0.0, auto_device=True, max_gap_s=0.1
            )
            found = check.device
            assert found is not None
            assert check.time_offset_s == 0.0  # the given offset stays the one applied
            truth = Rotation.from_matrix(np.array(rec.device.rotation))
            error = (Rotation.from_quat(np.array(found.rotation_xyzw)) * truth.inv()).as_rotvec()
            sigma = found.sigma_rotation_deg[2]
            assert sigma is not None
            assert abs(np.degrees(error[2])) <= 3.0 * sigma, (seed, clock)
