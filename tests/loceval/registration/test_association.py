"""Association in time: interpolation, nearest, offsets, gaps."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.errors import AssociationError
from loceval.registration.association import AssociationMethod, associate
from loceval.trajectory import Trajectory
from tests.loceval.conftest import T0_NS, smooth_trajectory


def _line(stamps_s: list[float], name: str = "ref") -> Trajectory:
    stamps = T0_NS + np.rint(np.asarray(stamps_s) * 1e9).astype(np.int64)
    x = np.asarray(stamps_s, dtype=float)
    return Trajectory(stamps, np.stack([x, 2 * x, 0 * x], 1), name=name)


def test_interpolation_is_algorithm_2() -> None:
    """p' = p_n + δ (p_{n+1} - p_n) at the estimate's stamps (reference-system paper Alg. 2)."""
    ref = _line([0.0, 0.1, 0.2, 0.3])
    est = _line([0.05, 0.1, 0.25], name="est")
    matched = associate(ref, est)
    np.testing.assert_allclose(matched.reference.positions_xyz[:, 0], [0.05, 0.1, 0.25])
    assert len(matched) == 3
    assert matched.dropped == 0


def test_interpolation_never_bridges_a_gap() -> None:
    """Estimate poses inside a reference gap longer than max_gap are dropped and counted."""
    ref = _line([0.0, 0.1, 0.2, 1.0, 1.1, 1.2])
    est = _line([0.05, 0.15, 0.5, 0.7, 1.05, 1.15, 2.0], name="est")
    matched = associate(ref, est, max_gap_ns=100_000_000)
    assert len(matched) == 4
    assert matched.dropped_gap == 2
    assert matched.dropped_outside == 1


def test_interpolated_orientation_is_slerp(rng: np.random.Generator) -> None:
    """A trajectory associated with itself at midpoints matches its own SLERP."""
    truth = smooth_trajectory(rng, n=200)
    mid = truth.select(np.arange(1, 199, 2))
    matched = associate(truth, mid)
    assert matched.reference.quat_xyzw is not None
    assert mid.quat_xyzw is not None
    np.testing.assert_allclose(
        np.abs((matched.reference.quat_xyzw * mid.quat_xyzw).sum(1)), 1.0, atol=1e-12
    )


def test_nearest_is_one_to_one_within_max_dt() -> None:
    """Two estimate poses nearest to one reference pose: the closer keeps it."""
    ref = _line([0.0, 1.0, 2.0, 3.0])
    est = _line([0.999, 1.004, 2.02, 3.0], name="est")
    matched = associate(
        ref, est, method=AssociationMethod.NEAREST, max_dt_ns=10_000_000, min_matches=2
    )
    np.testing.assert_array_equal(matched.estimate_index, [0, 3])
    assert matched.dropped_unmatched == 2
    with pytest.raises(AssociationError, match="Only 2 of 4 poses"):
        associate(ref, est, method=AssociationMethod.NEAREST, max_dt_ns=10_000_000)


def test_time_offset_is_added_to_the_estimate() -> None:
    """--time-offset shifts the estimate's stamps before matching."""
    ref = _line([0.0, 0.1, 0.2, 0.3, 0.4])
    est = _line([10.0, 10.1, 10.2, 10.3], name="est")
    matched = associate(ref, est, offset_ns=-10_000_000_000)
    assert len(matched) == 4
    assert matched.offset_ns == -10_000_000_000


def test_no_overlap_states_both_ranges() -> None:
    """No overlap in time raises an error naming both time ranges and the offset."""
    ref = _line([0.0, 0.1, 0.2, 0.3])
    est = _line([5.0, 5.1, 5.2], name="est")
    with pytest.raises(AssociationError, match=r"reference covers .* estimate .* covers .*offset"):
        associate(ref, est)
    with pytest.raises(AssociationError, match="max_gap"):
        associate(ref, est, max_gap_ns=0)


def test_large_inputs_are_linear(rng: np.random.Generator) -> None:
    """200,000 x 50,000 poses associate without an n x m matrix."""
    truth = smooth_trajectory(rng, n=200_000, rate_hz=1000.0)
    est = truth.select(np.arange(0, 200_000, 4))
    matched = associate(truth, est)
    assert len(matched) == 50_000
    np.testing.assert_allclose(matched.reference.positions_xyz, est.positions_xyz, atol=1e-12)
