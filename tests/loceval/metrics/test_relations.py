"""Pose relations, evo's matching and evo's RPE pairs on trajectories with known errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.errors import MetricError
from loceval.metrics.relations import (
    PoseRelation,
    ape_series,
    evo_pairs,
    rpe_series,
    scale_only,
)
from loceval.registration.stamps import match_nearest_seconds, seconds_of
from loceval.trajectory import Trajectory

N = 50


def _line(angle_deg: float = 0.0, shift: float = 0.0, scale: float = 1.0) -> Trajectory:
    """A straight walk along x (1 m per pose, 1 s apart), each pose turned about z."""
    stamps = np.arange(N, dtype=np.int64) * 1_000_000_000
    positions = np.zeros((N, 3))
    positions[:, 0] = np.arange(N) * scale
    positions[:, 1] = shift
    quats = Rotation.from_euler("z", np.full((N, 1), angle_deg), degrees=True).as_quat()
    return Trajectory(stamps_ns=stamps, positions_xyz=positions, quat_xyzw=quats, name="t")


def test_ape_relations_of_a_known_error() -> None:
    """A 0.5 m offset and a 10 deg turn give the relations' textbook values."""
    reference, estimate = _line(), _line(angle_deg=10.0, shift=0.5)
    theta = np.radians(10.0)
    rot_part = 2.0 * np.sqrt(2.0) * np.sin(theta / 2.0)
    expected = {
        PoseRelation.TRANS_PART: 0.5,
        PoseRelation.POINT_DISTANCE: 0.5,
        PoseRelation.ANGLE_DEG: 10.0,
        PoseRelation.ANGLE_RAD: theta,
        PoseRelation.ROT_PART: rot_part,
        PoseRelation.FULL: np.hypot(rot_part, 0.5),
    }
    for relation, value in expected.items():
        series = ape_series(reference, estimate, relation)
        np.testing.assert_allclose(series.values, value, rtol=1e-12, err_msg=relation.value)


def test_rpe_of_a_constant_offset_is_zero_and_of_a_scale_is_the_step() -> None:
    """A rigid offset leaves every motion unchanged; a scale of 1.1 adds 0.1 m per metre."""
    pairs = evo_pairs(_line(), _line(), delta=1, unit="f")
    offset = rpe_series(_line(), _line(shift=2.0), PoseRelation.TRANS_PART, pairs)
    np.testing.assert_allclose(offset.values, 0.0, atol=1e-12)
    scaled = rpe_series(_line(), _line(scale=1.1), PoseRelation.TRANS_PART, pairs)
    np.testing.assert_allclose(scaled.values, 0.1, rtol=1e-9)
    with pytest.raises(MetricError, match="point_distance"):
        rpe_series(_line(), _line(), PoseRelation.POINT_DISTANCE, pairs)


def test_rotation_relations_need_orientations() -> None:
    """A position-only side cannot give a rotation error; the message names the fix."""
    bare = Trajectory(stamps_ns=_line().stamps_ns, positions_xyz=_line().positions_xyz)
    with pytest.raises(MetricError, match="trans_part"):
        ape_series(_line(), bare, PoseRelation.ANGLE_DEG)
    assert ape_series(_line(), bare, PoseRelation.TRANS_PART).stats.max == 0.0


def test_pairs_by_frames_metres_and_all_pairs() -> None:
    """Consecutive pairs chain; all pairs start at every pose."""
    i, j = evo_pairs(_line(), _line(), delta=5, unit="f")
    assert i.tolist() == list(range(0, N - 5, 5))
    assert (j - i == 5).all()
    i, j = evo_pairs(_line(), _line(), delta=5, unit="f", all_pairs=True)
    assert i.size == N - 5
    i, j = evo_pairs(_line(), _line(scale=2.0), delta=4.0, unit="m")
    assert (j - i == 2).all()  # 2 m per pose along the estimate
    i, j = evo_pairs(_line(), _line(scale=2.0), delta=4.0, unit="m", from_reference=True)
    assert (j - i == 4).all()
    with pytest.raises(MetricError, match="whole number"):
        evo_pairs(_line(), _line(), delta=1.5, unit="f")


def test_angle_pairs_take_every_pair_within_the_tolerance() -> None:
    """Turning 1 deg per pose, all pairs 10 deg apart (+/- 15 %) are 9, 10 or 11 poses apart."""
    stamps = _line().stamps_ns
    quats = Rotation.from_euler("z", np.arange(N)[:, None], degrees=True).as_quat()
    turning = Trajectory(stamps_ns=stamps, positions_xyz=_line().positions_xyz, quat_xyzw=quats)
    i, j = evo_pairs(turning, turning, delta=10.0, unit="d", all_pairs=True, tolerance=0.15)
    assert set((j - i).tolist()) == {9, 10, 11}
    assert i.size == (N - 9) + (N - 10) + (N - 11)
    i, j = evo_pairs(turning, turning, delta=np.radians(9.5), unit="r")
    assert (j - i == 10).all()


def test_matching_in_float_seconds_takes_the_earlier_on_a_tie() -> None:
    """Nearest in float seconds, not one-to-one, the earlier neighbour on an exact tie."""
    reference = np.arange(5, dtype=np.int64) * 20_000_000 + 10_000_000_000
    estimate = np.array([10_010_000_000, 10_019_000_000, 10_021_000_000, 10_200_000_000])
    ref_idx, est_idx = match_nearest_seconds(reference, estimate, max_dt_s=0.0101)
    assert est_idx.tolist() == [0, 1, 2]  # the last is 120 ms away
    assert ref_idx.tolist() == [0, 1, 1]  # the tie goes to the earlier; two share pose 1
    ref_idx, est_idx = match_nearest_seconds(reference, estimate, max_dt_s=0.01, offset_s=0.01)
    assert ref_idx.tolist()[:1] == [1]


def test_the_shorter_side_is_matched_to_the_longer() -> None:
    """A sparse reference (AMCL) takes each of its poses' nearest estimate pose."""
    reference = np.array([10_000_000_000, 11_000_000_000])
    estimate = np.arange(0, 30, dtype=np.int64) * 50_000_000 + 10_004_000_000
    ref_idx, est_idx = match_nearest_seconds(reference, estimate, max_dt_s=0.01)
    assert ref_idx.tolist() == [0, 1]
    assert est_idx.tolist() == [0, 20]


def test_seconds_of_recovers_the_parsed_float() -> None:
    """A stamp read as float seconds and stored in ns converts back to the same float."""
    parsed = np.array([1311868220.910650, 1305031102.175304, 1.5])
    stamps = np.round(parsed.astype(np.longdouble) * 1_000_000_000).astype(np.int64)
    np.testing.assert_array_equal(seconds_of(stamps), parsed)


def test_scale_only_scales_about_the_origin() -> None:
    """evo's -s: the Sim(3) scale alone, without rotating or moving the estimate."""
    positions = np.random.default_rng(1).normal(size=(N, 3))
    reference = Trajectory(stamps_ns=_line().stamps_ns, positions_xyz=positions)
    estimate = Trajectory(stamps_ns=_line().stamps_ns, positions_xyz=positions * 0.5)
    scaled = scale_only(reference, estimate, poses=None)
    np.testing.assert_allclose(scaled.positions_xyz, reference.positions_xyz, atol=1e-9)
