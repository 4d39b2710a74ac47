"""Alignment in space: Umeyama SE3/Sim3, yaw, origin, calibrate, windows, degeneracy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.core.geometry import SimilarityTransform
from loceval.errors import AlignmentError
from loceval.registration.alignment import (
    AlignMethod,
    AlignWindow,
    align,
    align_umeyama,
    align_yaw,
)
from loceval.trajectory import Trajectory
from tests.loceval.conftest import smooth_trajectory


def _moved(traj: Trajectory, T: SimilarityTransform) -> Trajectory:
    return traj.transformed(T)


def test_se3_recovers_a_rigid_transform(truth: Trajectory) -> None:
    """Umeyama without scale finds the exact inverse of a rigid frame change."""
    T = SimilarityTransform(
        Rotation.from_euler("xyz", [5, -10, 70], degrees=True).as_matrix(), np.array([3.0, -1, 2])
    )
    est = _moved(truth, T)
    found = align(truth, est, method=AlignMethod.SE3)
    np.testing.assert_allclose(found.transform.as_matrix(), T.inverse().as_matrix(), atol=1e-9)
    assert found.poses_used == len(truth)


def test_sim3_recovers_the_scale(truth: Trajectory) -> None:
    """Umeyama with scale recovers a monocular SLAM's scale factor."""
    T = SimilarityTransform(Rotation.from_euler("z", 40, degrees=True).as_matrix(), np.ones(3), 0.3)
    found = align(truth, _moved(truth, T), method=AlignMethod.SIM3)
    assert found.transform.scale == pytest.approx(1 / 0.3)
    se3 = align(truth, _moved(truth, T), method=AlignMethod.SE3)
    assert se3.transform.scale == 1.0


def test_yaw_only_rotates_about_z(truth: Trajectory) -> None:
    """4-DoF alignment recovers a yaw + translation and leaves roll and pitch alone."""
    T = SimilarityTransform(Rotation.from_euler("z", -120, degrees=True).as_matrix(), np.ones(3))
    found = align(truth, _moved(truth, T), method=AlignMethod.YAW)
    np.testing.assert_allclose(found.transform.as_matrix(), T.inverse().as_matrix(), atol=1e-9)
    tilted = SimilarityTransform(
        Rotation.from_euler("x", 10, degrees=True).as_matrix(), np.zeros(3)
    )
    R = align(truth, _moved(truth, tilted), method=AlignMethod.YAW).transform.rotation
    np.testing.assert_allclose(R[2], [0, 0, 1], atol=1e-12)


def test_origin_and_calibrate_make_the_first_poses_coincide(truth: Trajectory) -> None:
    """T_C = Q_0 · P_0^-1 maps the first estimate pose onto the first reference pose."""
    T = SimilarityTransform(
        Rotation.from_euler("xyz", [1, 2, 3]).as_matrix(), np.array([4.0, 5, 6])
    )
    est = _moved(truth, T)
    for method in (AlignMethod.ORIGIN, AlignMethod.CALIBRATE):
        found = align(truth, est, method=method)
        np.testing.assert_allclose(found.transform.as_matrix(), T.inverse().as_matrix(), atol=1e-9)


def test_calibrate_at_a_given_time(rng: np.random.Generator) -> None:
    """--calibrate-at picks the matched sample nearest that many seconds after the start."""
    truth = smooth_trajectory(rng, n=300)
    est = truth.transformed(SimilarityTransform(np.eye(3), np.array([1.0, 0, 0])))
    found = align(truth, est, method=AlignMethod.CALIBRATE, calibrate_at_s=1.0)
    np.testing.assert_allclose(found.transform.translation, [-1, 0, 0], atol=1e-12)
    with pytest.raises(AlignmentError, match="after the last matched pose"):
        align(truth, est, method=AlignMethod.CALIBRATE, calibrate_at_s=100.0)


def test_origin_without_orientation_translates() -> None:
    """Position-only sources are aligned at the origin by translation only."""
    stamps = np.arange(3, dtype=np.int64)
    ref = Trajectory(stamps, np.array([[1.0, 1, 1], [2, 1, 1], [3, 1, 1]]))
    est = Trajectory(stamps, np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]))
    found = align(ref, est, method=AlignMethod.ORIGIN)
    np.testing.assert_allclose(found.transform.translation, [1, 1, 1])
    with pytest.raises(AlignmentError, match="position-only"):
        align(ref, est, method=AlignMethod.CALIBRATE)


def test_align_first_window(truth: Trajectory) -> None:
    """--align-first N / Ns estimates the transform from the leading poses only."""
    assert align(truth, truth, window=AlignWindow.parse("50")).poses_used == 50
    assert align(truth, truth, window=AlignWindow.parse("1s")).poses_used == 101
    notes = align(truth, truth, method=AlignMethod.ORIGIN, window=AlignWindow(poses=5)).warnings
    assert any("ignored" in n for n in notes)


@pytest.mark.parametrize("text", ["0", "-3", "abc", "0s", "nans"])
def test_bad_windows_are_rejected(text: str) -> None:
    """The alignment window takes a positive count or seconds."""
    with pytest.raises(AlignmentError, match="alignment window") as err:
        AlignWindow.parse(text)
    assert err.value.option == "align_first"


def test_collinear_points_are_degenerate() -> None:
    """Points on a line leave the rotation about it undetermined: an error, not a guess."""
    x = np.linspace(0, 5, 20)
    line = np.stack([x, 2 * x, 0 * x], 1)
    with pytest.raises(AlignmentError, match="lie on a line"):
        align_umeyama(line, line + 1.0)
    with pytest.raises(AlignmentError, match="at least 3"):
        align_umeyama(line[:2], line[:2])
    with pytest.raises(AlignmentError, match="horizontal extent"):
        align_yaw(np.zeros((5, 3)), np.zeros((5, 3)))


def test_none_is_identity(truth: Trajectory) -> None:
    """--align none keeps the estimate where it is."""
    found = align(truth, truth, method=AlignMethod.NONE)
    np.testing.assert_array_equal(found.transform.as_matrix(), np.eye(4))
