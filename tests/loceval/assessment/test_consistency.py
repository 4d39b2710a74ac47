"""NEES of reported covariances: synthetic verdicts, an independent loop, and nav2's AMCL."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from loceval.assessment.consistency import (
    ConsistencyVerdict,
    check_consistency,
    compute_nees,
    covariance_in_aligned_frame,
    is_planar,
    nees_values,
    rotation_errors_rotvec,
)
from loceval.errors import InputError, MetricError
from loceval.readers.rosbag import read_bag_trajectory
from loceval.registration.association import associate
from loceval.trajectory import Trajectory


def random_covariances(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """Return (n, 3, 3) random symmetric positive definite covariances of about ``scale``²."""
    a = rng.normal(0.0, scale, (n, 3, 3))
    return a @ a.transpose(0, 2, 1) + np.eye(3) * (0.1 * scale) ** 2


def draw_errors(rng: np.random.Generator, cov: np.ndarray) -> np.ndarray:
    """Return one independent error per pose, drawn from N(0, cov)."""
    chol = np.linalg.cholesky(cov)
    return (chol @ rng.normal(size=(cov.shape[0], 3, 1)))[:, :, 0]


def loop_nees(errors: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Independent computation: one np.linalg.solve per pose."""
    return np.array([e @ np.linalg.solve(s, e) for e, s in zip(errors, cov, strict=True)])


class TestSynthetic:
    """Errors drawn from the covariance a system reports, or from twice or half of it."""

    @pytest.mark.parametrize(
        ("reported_factor", "verdict"),
        [
            (1.0, ConsistencyVerdict.CONSISTENT),
            (2.0, ConsistencyVerdict.CONSERVATIVE),
            (0.5, ConsistencyVerdict.OVERCONFIDENT),
        ],
    )
    def test_verdicts(self, rng, reported_factor, verdict):
        """Correct, doubled and halved covariances read consistent, conservative, overconfident."""
        true_cov = random_covariances(rng, 2000, 0.05)
        errors = draw_errors(rng, true_cov)
        result = check_consistency(errors, reported_factor * true_cov)
        assert result.verdict is verdict
        assert result.nees_position.dof == 3
        assert not result.nees_position.planar
        # The mean NEES is dof / factor: 3, 1.5 and 6 within sampling error (sd 0.055).
        assert result.nees_position.mean == pytest.approx(3.0 / reported_factor, rel=0.08)
        if verdict is ConsistencyVerdict.CONSISTENT:
            assert result.nees_position.share_in_band == pytest.approx(0.95, abs=0.015)

    def test_equals_an_independent_loop(self, rng):
        """Vectorised NEES equals a per-pose np.linalg.solve loop."""
        cov = random_covariances(rng, 300, 0.1)
        errors = draw_errors(rng, cov)
        values, usable = nees_values(errors, cov)
        assert usable.all()
        np.testing.assert_allclose(values, loop_nees(errors, cov), rtol=1e-10)

    def test_band_of_the_mean(self, rng):
        """Independent poses: the band is chi2(N dof)/N; n_effective is about N."""
        cov = random_covariances(rng, 1000, 0.05)
        result = compute_nees(draw_errors(rng, cov), cov)
        n = 1000
        expected = chi2.ppf([0.025, 0.975], n * 3) / n
        np.testing.assert_allclose(result.band95_independent, expected)
        assert result.n_effective == pytest.approx(n, rel=0.1)
        assert result.to_dict() == {
            "mean": result.mean,
            "dof": 3,
            "band95": list(result.band95),
            "share_in_band": result.share_in_band,
        }

    def test_correlated_errors_widen_the_band(self, rng):
        """Errors that persist for 20 poses get a band about sqrt(20) times wider."""
        cov = np.broadcast_to(np.diag([0.01, 0.02, 0.005]), (4000, 3, 3))
        errors = np.repeat(draw_errors(rng, cov[:200]), 20, axis=0)
        result = compute_nees(errors, cov)
        assert result.n_effective < 400
        width = result.band95[1] - result.band95[0]
        width_ind = result.band95_independent[1] - result.band95_independent[0]
        assert width > 3.0 * width_ind

    def test_planar_uses_the_xy_block(self, rng):
        """Zero z variance is detected: dof 2 and the x-y block."""
        cov = random_covariances(rng, 500, 0.05)
        cov[:, 2, :] = 0.0
        cov[:, :, 2] = 0.0
        errors = draw_errors(rng, cov + np.diag([0.0, 0.0, 1.0]))
        errors[:, 2] = rng.normal(0, 5.0, 500)  # whatever z does is not judged
        result = check_consistency(errors, cov)
        assert result.nees_position.planar
        assert result.nees_position.dof == 2
        np.testing.assert_allclose(
            result.nees_position.values, loop_nees_2d(errors[:, :2], cov[:, :2, :2])
        )
        assert "x-y block (dof 2)" in result.warnings[0]

    def test_planar_detection(self, rng):
        """Zero, placeholder or constant-while-x-y-varies z is planar; constant 3-D is not."""
        cov = random_covariances(rng, 50, 0.05)
        const = np.broadcast_to(np.diag([0.01, 0.01, 0.04]), (50, 3, 3)).copy()
        assert not is_planar(cov)
        assert not is_planar(const)
        for z in (0.0, 1e6):
            flat = cov.copy()
            flat[:, 2, 2] = z
            assert is_planar(flat)
        fixed_z = cov.copy()
        fixed_z[:, 2, 2] = 0.3
        assert is_planar(fixed_z)

    def test_singular_covariances_are_skipped(self, rng, caplog):
        """Singular covariances are skipped, counted and logged."""
        cov = random_covariances(rng, 100, 0.05)
        cov[:10] = np.diag([0.01, 0.0, 0.01])
        result = compute_nees(draw_errors(rng, cov + 1e-6 * np.eye(3)), cov, planar=False)
        assert result.skipped == 10
        assert result.n == 90
        assert np.isnan(result.values[:10]).all()
        assert "10 poses with a singular position covariance" in caplog.text

    def test_rotation_nees_and_overall_verdict(self, rng):
        """Rotation NEES uses world-axis rotation vectors; an overconfident block decides."""
        n = 1500
        ref = Rotation.random(n, random_state=rng)
        rot_cov = random_covariances(rng, n, 0.02)
        delta = draw_errors(rng, rot_cov)
        est = Rotation.from_rotvec(delta) * ref
        rotvec = rotation_errors_rotvec(ref.as_quat(), est.as_quat())
        np.testing.assert_allclose(rotvec, delta, atol=1e-12)
        pos_cov = random_covariances(rng, n, 0.05)
        pos = draw_errors(rng, pos_cov)
        good = check_consistency(pos, pos_cov, rotation_errors=rotvec, rotation_cov=rot_cov)
        assert good.verdict is ConsistencyVerdict.CONSISTENT
        assert good.nees_rotation is not None
        assert good.nees_rotation.dof == 3
        bad = check_consistency(
            pos, 2.0 * pos_cov, rotation_errors=rotvec, rotation_cov=0.5 * rot_cov
        )
        assert bad.nees_position.verdict is ConsistencyVerdict.CONSERVATIVE
        assert bad.verdict is ConsistencyVerdict.OVERCONFIDENT
        assert bad.to_dict()["nees_rotation"] is not None

    def test_aligned_frame_covariance(self, rng):
        """Sim(3) maps covariances to s² R S Rᵀ; NEES of mapped errors is unchanged."""
        cov = random_covariances(rng, 200, 0.05)
        errors = draw_errors(rng, cov)
        rot = Rotation.random(random_state=rng).as_matrix()
        mapped = covariance_in_aligned_frame(cov, rotation=rot, scale=2.0)
        np.testing.assert_allclose(mapped[7], 4.0 * rot @ cov[7] @ rot.T)
        before, _ = nees_values(errors, cov)
        after, _ = nees_values(2.0 * errors @ rot.T, mapped)
        np.testing.assert_allclose(after, before, rtol=1e-9)

    def test_bad_inputs(self, rng):
        """Mismatched shapes, NaN, too few usable poses and half a rotation input raise."""
        cov = random_covariances(rng, 20, 0.05)
        errors = draw_errors(rng, cov)
        with pytest.raises(InputError, match=r"\(N, 3\) errors and \(N, 3, 3\)"):
            compute_nees(errors[:, :2], cov)
        with pytest.raises(InputError, match="NaN or inf"):
            nees_values(np.full((20, 3), np.nan), cov)
        with pytest.raises(MetricError, match="Only 5 of 20 poses"):
            compute_nees(errors, np.concatenate([cov[:5], np.zeros((15, 3, 3))]), planar=False)
        with pytest.raises(InputError, match="both the rotation errors"):
            check_consistency(errors, cov, rotation_errors=errors)
        with pytest.raises(InputError, match="scale must be positive"):
            covariance_in_aligned_frame(cov, rotation=np.eye(3), scale=0.0)
        with pytest.raises(InputError, match="'position' or 'rotation'"):
            compute_nees(errors, cov, what="velocity")


def loop_nees_2d(errors: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Independent computation for 2-D blocks."""
    return np.array([e @ np.linalg.solve(s, e) for e, s in zip(errors, cov, strict=True)])


@pytest.mark.public_data
def test_nav2_amcl_nees_equals_an_independent_computation(public_data: Path):
    """AMCL's /amcl_pose covariance against tf map->base_link: planar NEES as a plain loop."""
    bag = public_data / "nav2_turtlebot.mcap"
    rows = []
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == "/amcl_pose"]
        for conn, _, raw in reader.messages(conns):
            msg = reader.deserialize(raw, conn.msgtype)
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            rows.append((stamp, p.x, p.y, p.z, q.x, q.y, q.z, q.w, *msg.pose.covariance))
    table = np.array(rows)
    amcl = Trajectory(
        table[:, 0].astype(np.int64),
        table[:, 1:4],
        table[:, 4:8],
        name="AMCL",
        cov6=table[:, 8:].reshape(-1, 6, 6),
    )
    reference = read_bag_trajectory(bag, "tf:map:base_link")
    matched = associate(reference, amcl)
    est, ref = matched.estimate, matched.reference
    assert est.cov6 is not None
    # Both are in the map frame, so the identity is the alignment.
    errors = est.positions_xyz - ref.positions_xyz
    rot_errors = rotation_errors_rotvec(ref.quat_xyzw, est.quat_xyzw)
    result = check_consistency(
        errors, est.cov6[:, :3, :3], rotation_errors=rot_errors, rotation_cov=est.cov6[:, 3:, 3:]
    )
    # Independent computation: a loop over poses with the x-y block and the yaw variance.
    expected_pos = np.array(
        [e[:2] @ np.linalg.solve(c[:2, :2], e[:2]) for e, c in zip(errors, est.cov6, strict=True)]
    )
    expected_yaw = np.array(
        [r[2] ** 2 / c[5, 5] for r, c in zip(rot_errors, est.cov6, strict=True)]
    )
    position, rotation = result.nees_position, result.nees_rotation
    assert rotation is not None
    assert position.planar
    assert position.dof == 2
    assert rotation.planar
    assert rotation.dof == 1
    assert position.skipped == 0
    np.testing.assert_allclose(position.values, expected_pos, rtol=1e-9)
    np.testing.assert_allclose(rotation.values, expected_yaw, rtol=1e-9)
    assert position.mean == pytest.approx(expected_pos.mean(), rel=1e-12)
    # tf map->base_link is AMCL's own map->odom composed with odometry, so the errors are
    # far below AMCL's reported spread: measured with this code, position NEES mean 0.0231
    # (dof 2, band 1.38-2.74 over n_eff 32.8 of 129 poses), yaw 0.0107 (dof 1); the loop
    # above agrees to 1e-9. AMCL is conservative against this reference.
    assert position.n == 129
    assert position.mean == pytest.approx(0.02313, rel=1e-3)
    assert rotation.mean == pytest.approx(0.01065, rel=1e-3)
    assert result.verdict is ConsistencyVerdict.CONSERVATIVE
