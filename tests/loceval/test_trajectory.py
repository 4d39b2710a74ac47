"""Trajectory value type and geometry helpers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.core.geometry import (
    SimilarityTransform,
    compose_quat,
    conjugate_quat,
    relative_angle_deg,
    slerp_pairs,
)
from loceval.errors import InputError, TrajectoryError
from loceval.trajectory import Trajectory


def test_arrays_are_copied_and_read_only(truth: Trajectory) -> None:
    """The caller's arrays stay writable and the trajectory's cannot be changed."""
    stamps = truth.stamps_ns.copy()
    traj = Trajectory(stamps, truth.positions_xyz, truth.quat_xyzw)
    stamps[0] = 0
    assert traj.stamps_ns[0] != 0
    with pytest.raises(ValueError, match="read-only"):
        traj.positions_xyz[0, 0] = 1.0


@pytest.mark.parametrize(
    ("stamps", "positions", "quat", "match"),
    [
        (np.array([0.0, 1.0]), np.zeros((2, 3)), None, "integer array"),
        (np.array([0, 1]), np.zeros((3, 3)), None, r"shape \(2, 3\)"),
        (np.array([0, 1]), np.array([[0, 0, 0], [np.nan, 0, 0]]), None, "NaN"),
        (np.array([1, 0]), np.zeros((2, 3)), None, "strictly increasing"),
        (np.array([0, 1]), np.zeros((2, 3)), np.ones((2, 4)), "unit quaternions"),
        (np.array([0, 1]), np.zeros((2, 3)), np.ones((2, 3)), r"shape \(2, 4\)"),
    ],
)
def test_invalid_arrays_are_rejected(stamps, positions, quat, match) -> None:
    """Wrong dtype, shape, NaN, unsorted stamps and non-unit quaternions raise TrajectoryError."""
    with pytest.raises(TrajectoryError, match=match):
        Trajectory(stamps, positions, quat, name="x")


def test_facts() -> None:
    """Duration, length, rate and gaps of a simple path."""
    stamps = np.array([0, 100_000_000, 200_000_000, 500_000_000], dtype=np.int64)
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1]], dtype=float)
    traj = Trajectory(stamps, positions)
    assert traj.duration_s == pytest.approx(0.5)
    assert traj.length_m == pytest.approx(3.0)
    assert traj.rate_hz == pytest.approx(10.0)
    assert traj.gaps(100_000_000) == [(200_000_000, 500_000_000)]
    np.testing.assert_allclose(traj.distances_m(), [0, 1, 2, 3])
    assert not traj.has_orientation


def test_transformed_maps_positions_and_orientations(truth: Trajectory) -> None:
    """A similarity transform moves positions by sRx+t and rotates orientations by R."""
    rot = Rotation.from_euler("xyz", [10, -20, 30], degrees=True)
    T = SimilarityTransform(rot.as_matrix(), np.array([1.0, 2.0, 3.0]), 2.0)
    moved = truth.transformed(T)
    np.testing.assert_allclose(
        moved.positions_xyz, 2.0 * rot.apply(np.array(truth.positions_xyz)) + [1, 2, 3]
    )
    assert truth.quat_xyzw is not None
    assert moved.quat_xyzw is not None
    angles = relative_angle_deg(
        moved.quat_xyzw, (rot * Rotation.from_quat(truth.quat_xyzw)).as_quat()
    )
    assert angles.max() < 1e-6


def test_body_offset_moves_along_the_body_axes() -> None:
    """A device offset is applied in the body frame: T_world_body · offset."""
    yaw90 = Rotation.from_euler("z", 90, degrees=True).as_quat()
    traj = Trajectory(
        np.arange(3, dtype=np.int64), np.zeros((3, 3)), np.tile(yaw90, (3, 1)), name="gt"
    )
    offset = SimilarityTransform(np.eye(3), np.array([1.0, 0.0, 0.0]))
    moved = traj.with_body_offset(offset)
    np.testing.assert_allclose(moved.positions_xyz, np.tile([0.0, 1.0, 0.0], (3, 1)), atol=1e-12)


def test_body_offset_needs_orientation() -> None:
    """A translating device offset on a position-only trajectory is refused."""
    traj = Trajectory(np.arange(3, dtype=np.int64), np.zeros((3, 3)), name="uwb")
    offset = SimilarityTransform(np.eye(3), np.array([0.1, 0.0, 0.0]))
    with pytest.raises(TrajectoryError, match="no orientations"):
        traj.with_body_offset(offset)


def test_transform_algebra(rng: np.random.Generator) -> None:
    """compose, inverse and as_matrix agree with 4x4 matrix algebra."""
    a = SimilarityTransform(Rotation.random(random_state=1).as_matrix(), rng.normal(size=3), 1.5)
    b = SimilarityTransform(Rotation.random(random_state=2).as_matrix(), rng.normal(size=3), 0.7)
    np.testing.assert_allclose(a.compose(b).as_matrix(), a.as_matrix() @ b.as_matrix())
    np.testing.assert_allclose(a.compose(a.inverse()).as_matrix(), np.eye(4), atol=1e-12)
    c = SimilarityTransform.from_matrix(a.as_matrix())
    np.testing.assert_allclose(c.as_matrix(), a.as_matrix())
    assert c.scale == pytest.approx(1.5)


@pytest.mark.parametrize(
    ("matrix", "match"),
    [
        (np.eye(3), "4x4"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), "positive determinant"),
        (np.diag([1.0, 2.0, 3.0, 1.0]), "scaled rotation"),
    ],
)
def test_bad_matrices_are_rejected(matrix, match) -> None:
    """Matrices that are not similarity transforms raise InputError."""
    with pytest.raises(InputError, match=match):
        SimilarityTransform.from_matrix(matrix)


def test_slerp_pairs_halfway() -> None:
    """Halfway between identity and a 90° yaw is a 45° yaw."""
    q0 = np.array([[0.0, 0.0, 0.0, 1.0]])
    q1 = Rotation.from_euler("z", [90], degrees=True).as_quat()
    mid = slerp_pairs(q0, q1, np.array([0.5]))
    assert Rotation.from_quat(mid).as_euler("xyz", degrees=True)[0, 2] == pytest.approx(45.0)


def test_compose_quat_matches_scipy() -> None:
    """The vectorized Hamilton product equals scipy's composition, with conjugate as inverse."""
    a = Rotation.random(100, random_state=3)
    b = Rotation.random(100, random_state=4)
    ours = compose_quat(a.as_quat(), b.as_quat())
    np.testing.assert_allclose(np.abs((ours * (a * b).as_quat()).sum(1)), 1.0, atol=1e-12)
    identity = compose_quat(a.as_quat(), conjugate_quat(a.as_quat()))
    np.testing.assert_allclose(np.abs(identity[:, 3]), 1.0, atol=1e-12)


def test_names_are_one_line() -> None:
    """Line ends and tabs in a name become single spaces; NUL becomes a visible U+FFFD."""
    traj = Trajectory(np.arange(3, dtype=np.int64), np.zeros((3, 3)), name=" RTAB\r\nMap\t\x00v2 ")
    assert traj.name == "RTAB Map \ufffdv2"


def test_positions_beyond_any_site_are_rejected() -> None:
    """A coordinate beyond 1e9 m is not metres: refused before it overflows the statistics."""
    positions = np.zeros((3, 3))
    positions[1, 0] = 1e160
    with pytest.raises(TrajectoryError, match="beyond"):
        Trajectory(np.arange(3, dtype=np.int64), positions)


class TestCovariance:
    """Optional per-pose 6x6 covariances: checked, carried and transformed."""

    @staticmethod
    def with_cov(rng: np.random.Generator, n: int = 20) -> Trajectory:
        a = rng.normal(0.0, 0.1, (n, 6, 6))
        cov = a @ a.transpose(0, 2, 1)
        positions = rng.normal(size=(n, 3))
        quat = Rotation.random(n, random_state=rng).as_quat()
        return Trajectory(np.arange(n, dtype=np.int64), positions, quat, cov6=cov)

    def test_default_is_none(self, truth: Trajectory) -> None:
        """Trajectories without covariance keep None through every operation."""
        assert truth.cov6 is None
        assert not truth.has_covariance
        assert truth.select(np.arange(3)).cov6 is None
        assert truth.transformed(SimilarityTransform.identity()).cov6 is None

    def test_copied_read_only_and_selected(self, rng: np.random.Generator) -> None:
        """The covariance is a read-only copy and follows select()."""
        traj = self.with_cov(rng)
        assert traj.cov6 is not None
        assert traj.has_covariance
        assert not traj.cov6.flags.writeable
        picked = traj.select(np.array([2, 5]))
        assert picked.cov6 is not None
        np.testing.assert_array_equal(picked.cov6, traj.cov6[[2, 5]])
        for kept in (traj.shifted(5), traj.without_orientation()):
            assert kept.cov6 is not None
            np.testing.assert_array_equal(kept.cov6, traj.cov6)

    def test_transformed_rotates_and_scales(self, rng: np.random.Generator) -> None:
        """A Sim(3) maps the position block to s² R S Rᵀ and the rotation block to R S Rᵀ."""
        traj = self.with_cov(rng)
        rot = Rotation.random(random_state=rng).as_matrix()
        moved = traj.transformed(SimilarityTransform(rot, np.array([1.0, 2.0, 3.0]), 2.0))
        assert moved.cov6 is not None
        assert traj.cov6 is not None
        np.testing.assert_allclose(moved.cov6[4, :3, :3], 4.0 * rot @ traj.cov6[4, :3, :3] @ rot.T)
        np.testing.assert_allclose(moved.cov6[4, 3:, 3:], rot @ traj.cov6[4, 3:, 3:] @ rot.T)
        np.testing.assert_allclose(moved.cov6[4, :3, 3:], 2.0 * rot @ traj.cov6[4, :3, 3:] @ rot.T)

    def test_body_offset_adds_the_lever_arm(self) -> None:
        """A yaw variance moves a point 1 m ahead sideways: its y variance grows by σ²·1 m²."""
        cov = np.zeros((3, 6, 6))
        cov[:, 5, 5] = 0.01
        traj = Trajectory(
            np.arange(3, dtype=np.int64),
            np.zeros((3, 3)),
            np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)),
            cov6=cov,
        )
        moved = traj.with_body_offset(SimilarityTransform(np.eye(3), np.array([1.0, 0.0, 0.0])))
        assert moved.cov6 is not None
        # δp = δθ × lever = (0, 0, δψ) × (1, 0, 0) = (0, δψ, 0): var y = 0.01, cov(y, ψ) = 0.01.
        np.testing.assert_allclose(moved.cov6[0, 1, 1], 0.01)
        np.testing.assert_allclose(moved.cov6[0, 1, 5], 0.01)
        np.testing.assert_allclose(moved.cov6[0, 0, 0], 0.0)
        np.testing.assert_allclose(moved.cov6[0, 5, 5], 0.01)

    @pytest.mark.parametrize(
        ("cov", "match"),
        [
            (np.zeros((3, 3, 3)), r"shape \(3, 6, 6\)"),
            (np.full((3, 6, 6), np.nan), "NaN or inf"),
            (np.triu(np.ones((3, 6, 6))), "must be symmetric"),
        ],
    )
    def test_invalid_covariances(self, cov: np.ndarray, match: str) -> None:
        """Wrong shape, NaN and asymmetric covariances are rejected."""
        with pytest.raises(TrajectoryError, match=match):
            Trajectory(np.arange(3, dtype=np.int64), np.zeros((3, 3)), cov6=cov)
