"""The NumPy rotations agree with scipy's Rotation (the oracle) on the operations the core uses."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation as ScipyRotation

from loceval.core.rotation import Rotation, compose_quat, conjugate_quat


def _random_quat(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_matrix_round_trip_matches_scipy(rng: np.random.Generator) -> None:
    """Quaternion -> matrix -> quaternion gives scipy's matrices and quaternions."""
    q = _random_quat(rng, 500)
    matrices = Rotation.from_quat(q).as_matrix()
    np.testing.assert_allclose(matrices, ScipyRotation.from_quat(q).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(
        Rotation.from_matrix(matrices).as_quat(),
        ScipyRotation.from_matrix(matrices).as_quat(),
        atol=1e-15,
    )


def test_from_matrix_covers_every_branch(rng: np.random.Generator) -> None:
    """Rotations by π about each axis and near identity pick each of the four formulas."""
    cases = np.array(
        [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    )
    cases = np.concatenate([cases, Rotation.from_quat(_random_quat(rng, 20)).as_matrix()])
    np.testing.assert_allclose(
        Rotation.from_matrix(cases).as_quat(),
        ScipyRotation.from_matrix(cases).as_quat(),
        atol=1e-15,
    )
    # Rx(π) is the quaternion (1, 0, 0, 0), by hand.
    np.testing.assert_allclose(Rotation.from_matrix(cases[0]).as_quat(), [1.0, 0.0, 0.0, 0.0])


def test_from_matrix_projects_rounded_matrices_like_scipy(rng: np.random.Generator) -> None:
    """A matrix printed with four decimals is projected onto the nearest rotation, as scipy does."""
    matrices = np.round(Rotation.from_quat(_random_quat(rng, 50)).as_matrix(), 4)
    np.testing.assert_allclose(
        Rotation.from_matrix(matrices).as_quat(),
        ScipyRotation.from_matrix(matrices).as_quat(),
        atol=1e-12,
    )


def test_from_matrix_refuses_a_reflection() -> None:
    """A matrix with a negative determinant is no rotation."""
    with pytest.raises(ValueError, match=r"determinant -1\.0"):
        Rotation.from_matrix(np.diag([1.0, 1.0, -1.0]))


def test_rotation_vectors_match_scipy(rng: np.random.Generator) -> None:
    """log and exp agree with scipy, also below the Taylor-series threshold and at zero."""
    q = _random_quat(rng, 300)
    tiny = Rotation.from_rotvec(rng.normal(scale=1e-5, size=(5, 3))).as_quat()
    q = np.concatenate([q, tiny, [[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, -1.0]]])
    np.testing.assert_allclose(
        Rotation.from_quat(q).as_rotvec(), ScipyRotation.from_quat(q).as_rotvec(), atol=1e-15
    )
    v = rng.normal(scale=2.0, size=(300, 3))
    v[:5] *= 1e-6
    np.testing.assert_allclose(
        Rotation.from_rotvec(v).as_quat(), ScipyRotation.from_rotvec(v).as_quat(), atol=1e-15
    )
    np.testing.assert_allclose(
        Rotation.from_quat(q).magnitude(), ScipyRotation.from_quat(q).magnitude(), atol=1e-15
    )


def test_apply_compose_and_index_match_scipy(rng: np.random.Generator) -> None:
    """Applying (also inverse), composing with broadcasting and indexing agree with scipy."""
    q, p = _random_quat(rng, 100), _random_quat(rng, 1)[0]
    v = rng.normal(size=(100, 3))
    ours, theirs = Rotation.from_quat(q), ScipyRotation.from_quat(q)
    np.testing.assert_allclose(ours.apply(v), theirs.apply(v), atol=1e-14)
    np.testing.assert_allclose(
        ours.apply(v, inverse=True), theirs.apply(v, inverse=True), atol=1e-14
    )
    np.testing.assert_allclose(ours.apply(v[0]), theirs.apply(v[0]), atol=1e-14)
    composed = (ours * Rotation.from_quat(p)).as_matrix()
    np.testing.assert_allclose(
        composed, (theirs * ScipyRotation.from_quat(p)).as_matrix(), atol=1e-14
    )
    index = np.array([3, 1, 4, 1, 5])
    np.testing.assert_allclose(ours[index].as_quat(), theirs[index].as_quat(), atol=0.0)
    assert len(ours[index]) == 5
    assert ours[2].single
    np.testing.assert_allclose(ours.inv().as_matrix(), theirs.inv().as_matrix(), atol=1e-15)


def test_from_euler_matches_scipy(rng: np.random.Generator) -> None:
    """Fixed-axis (URDF rpy) and moving-axis sequences agree with scipy."""
    angles = rng.uniform(-np.pi, np.pi, size=(50, 3))
    for seq in ("xyz", "ZYX", "zxz"):
        np.testing.assert_allclose(
            Rotation.from_euler(seq, angles).as_matrix(),
            ScipyRotation.from_euler(seq, angles).as_matrix(),
            atol=1e-14,
        )
    np.testing.assert_allclose(
        Rotation.from_euler("xyz", angles[0]).as_matrix(),
        ScipyRotation.from_euler("xyz", angles[0]).as_matrix(),
        atol=1e-14,
    )
    # Rz(90°) maps x to y, by hand.
    np.testing.assert_allclose(
        Rotation.from_euler("z", 90.0, degrees=True).apply(np.array([1.0, 0.0, 0.0])),
        [0.0, 1.0, 0.0],
        atol=1e-15,
    )


@pytest.mark.parametrize(
    ("seq", "match"),
    [("xYz", "all lower or all upper"), ("xyzx", "1 to 3"), ("xw", "names 'w'")],
)
def test_from_euler_refuses_bad_sequences(seq: str, match: str) -> None:
    """A mixed-case, too long or unknown-axis sequence is refused."""
    with pytest.raises(ValueError, match=match):
        Rotation.from_euler(seq, np.zeros(len(seq)))


def test_bad_shapes_and_zero_quaternions_are_refused() -> None:
    """Wrong shapes and a zero quaternion raise, naming the problem."""
    with pytest.raises(ValueError, match="zero norm"):
        Rotation.from_quat(np.zeros(4))
    with pytest.raises(ValueError, match=r"shape \(4,\) or \(N, 4\)"):
        Rotation(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"shape \(3, 3\) or \(N, 3, 3\)"):
        Rotation.from_matrix(np.eye(4))
    with pytest.raises(TypeError, match="no length"):
        len(Rotation.from_quat(np.array([0.0, 0.0, 0.0, 1.0])))
    with pytest.raises(TypeError, match="cannot be indexed"):
        Rotation.from_quat(np.array([0.0, 0.0, 0.0, 1.0]))[0]


def test_compose_and_conjugate_undo_each_other(rng: np.random.Generator) -> None:
    """q ∘ q⁻¹ is the identity, and composition matches scipy's product."""
    a, b = _random_quat(rng, 40), _random_quat(rng, 40)
    np.testing.assert_allclose(
        np.abs(compose_quat(a, conjugate_quat(a))),
        np.tile([0.0, 0.0, 0.0, 1.0], (40, 1)),
        atol=1e-15,
    )
    np.testing.assert_allclose(
        compose_quat(a, b),
        (ScipyRotation.from_quat(a) * ScipyRotation.from_quat(b)).as_quat(),
        atol=1e-15,
    )
