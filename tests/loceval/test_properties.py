"""Invariants checked over random inputs (hypothesis)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from loceval.core.geometry import SimilarityTransform
from loceval.metrics.pose_errors import compute_ate, compute_rpe
from loceval.registration.alignment import AlignMethod, align, align_umeyama
from loceval.registration.association import AssociationMethod, associate

from .conftest import smooth_trajectory

seeds = st.integers(min_value=0, max_value=2**32 - 1)


def _random_transform(seed: int, *, with_scale: bool) -> SimilarityTransform:
    rng = np.random.default_rng(seed)
    scale = float(rng.uniform(0.2, 5.0)) if with_scale else 1.0
    return SimilarityTransform(
        Rotation.random(random_state=seed).as_matrix(), rng.uniform(-100, 100, 3), scale
    )


@given(seed=seeds, with_scale=st.booleans())
def test_umeyama_recovers_a_random_transform(seed: int, *, with_scale: bool) -> None:
    """Umeyama recovers a random SE3 / Sim3 from noise-free correspondences."""
    rng = np.random.default_rng(seed)
    src = rng.normal(size=(50, 3)) * [3.0, 2.0, 1.0]
    T = _random_transform(seed, with_scale=with_scale)
    found = align_umeyama(src, T.apply_positions(src), with_scale=with_scale)
    np.testing.assert_allclose(found.as_matrix(), T.as_matrix(), atol=1e-7 * max(1.0, T.scale))


@given(seed=seeds)
def test_ate_after_se3_is_invariant_to_a_rigid_move(seed: int) -> None:
    """Moving the estimate rigidly does not change its ATE after SE3 alignment."""
    rng = np.random.default_rng(seed)
    truth = smooth_trajectory(rng, n=200)
    noisy = type(truth)(
        truth.stamps_ns, truth.positions_xyz + rng.normal(0, 0.05, (200, 3)), truth.quat_xyzw
    )
    moved = noisy.transformed(_random_transform(seed, with_scale=False))
    errors = []
    for est in (noisy, moved):
        a = align(truth, est, method=AlignMethod.SE3)
        errors.append(compute_ate(truth, est.transformed(a.transform))[0].values)
    np.testing.assert_allclose(errors[0], errors[1], atol=1e-8)


@given(seed=seeds)
def test_rpe_is_invariant_to_a_global_move_of_both(seed: int) -> None:
    """Moving reference and estimate by the same rigid transform does not change RPE."""
    rng = np.random.default_rng(seed)
    truth = smooth_trajectory(rng, n=100)
    est = type(truth)(
        truth.stamps_ns, truth.positions_xyz + rng.normal(0, 0.05, (100, 3)), truth.quat_xyzw
    )
    T = _random_transform(seed, with_scale=False)
    before = compute_rpe(truth, est)[0].values
    after = compute_rpe(truth.transformed(T), est.transformed(T))[0].values
    np.testing.assert_allclose(before, after, atol=1e-8)


@given(seed=seeds, step=st.integers(min_value=1, max_value=7))
def test_interpolated_self_association_has_zero_error(seed: int, step: int) -> None:
    """A trajectory sampled from itself, associated by interpolation, has zero ATE."""
    rng = np.random.default_rng(seed)
    truth = smooth_trajectory(rng, n=300)
    sample = truth.select(np.arange(0, 300, step))
    matched = associate(truth, sample)
    ate_t, ate_r = compute_ate(matched.reference, matched.estimate)
    assert ate_t.stats.max < 1e-9
    assert ate_r is not None
    assert ate_r.stats.max < 1e-5


@given(seed=seeds, max_dt_ms=st.integers(min_value=0, max_value=30))
def test_nearest_is_one_to_one_within_max_dt(seed: int, max_dt_ms: int) -> None:
    """Nearest association never reuses a reference pose and never exceeds max dt."""
    rng = np.random.default_rng(seed)
    ref_stamps = np.cumsum(rng.integers(5_000_000, 20_000_000, 300))
    est_stamps = np.unique(rng.integers(0, int(ref_stamps[-1]), 200))
    ref = type(smooth_trajectory(rng, n=3))(ref_stamps, np.zeros((300, 3)))
    est = type(ref)(est_stamps, np.zeros((est_stamps.size, 3)))
    max_dt_ns = max_dt_ms * 1_000_000
    matched = associate(
        ref, est, method=AssociationMethod.NEAREST, max_dt_ns=max_dt_ns, min_matches=0
    )
    t_est = est_stamps[matched.estimate_index]
    nearest = np.abs(ref_stamps[None, :] - t_est[:, None]).argmin(axis=1)  # small: 300 x 200
    assert np.unique(nearest).size == nearest.size
    assert (np.abs(ref_stamps[nearest] - t_est) <= max_dt_ns).all()
    assert len(matched) + matched.dropped == est_stamps.size
