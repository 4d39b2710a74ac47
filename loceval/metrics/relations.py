"""Pose relations: which part of a pose error is measured (evo's ``--pose_relation``).

The absolute error of a matched pose is ``E_i = Q_i^-1 P_i`` (reference Q, aligned estimate
P), the relative error of a pair ``E_ij = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``. A relation maps
each E to one number:

- ``trans_part``: the length of E's translation, metres;
- ``rot_part``: ``||R(E) - I||_F``, unit-less;
- ``angle_deg`` / ``angle_rad``: the angle of R(E);
- ``full``: ``||E - I||_F`` of the 4x4 matrix, unit-less;
- ``point_distance``: the distance of the two positions (APE only; orientations unused).

All of it is vectorised over the poses or pairs.
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.core.arrays import FloatArray, IntArray
from loceval.core.geometry import SimilarityTransform
from loceval.errors import MetricError
from loceval.metrics.pose_errors import ErrorSeries
from loceval.registration.alignment import align_umeyama
from loceval.trajectory import Trajectory

__all__ = [
    "RELATION_UNITS",
    "PoseRelation",
    "ape_series",
    "evo_pairs",
    "rpe_series",
    "scale_only",
]


class PoseRelation(StrEnum):
    """Which part of a pose error is measured."""

    TRANS_PART = "trans_part"
    ROT_PART = "rot_part"
    ANGLE_DEG = "angle_deg"
    ANGLE_RAD = "angle_rad"
    FULL = "full"
    POINT_DISTANCE = "point_distance"


RELATION_UNITS = {
    PoseRelation.TRANS_PART: "m",
    PoseRelation.ROT_PART: "",
    PoseRelation.ANGLE_DEG: "deg",
    PoseRelation.ANGLE_RAD: "rad",
    PoseRelation.FULL: "",
    PoseRelation.POINT_DISTANCE: "m",
}
"""The unit of each relation's errors ("" for the unit-less ones)."""

_NEEDS_ROTATION = frozenset(
    {PoseRelation.ROT_PART, PoseRelation.ANGLE_DEG, PoseRelation.ANGLE_RAD, PoseRelation.FULL}
)


def _matrices(trajectory: Trajectory) -> FloatArray:
    """Return the (N, 3, 3) rotation matrices of a trajectory with orientations."""
    if trajectory.quat_xyzw is None:  # checked by the callers
        msg = f"{trajectory.name or 'The trajectory'} has no orientations."
        raise MetricError(msg)
    out: FloatArray = Rotation.from_quat(trajectory.quat_xyzw).as_matrix()
    return out


def _require_orientations(relation: PoseRelation, *trajectories: Trajectory) -> None:
    if relation not in _NEEDS_ROTATION:
        return
    for trajectory in trajectories:
        if trajectory.quat_xyzw is None:
            msg = (
                f"The pose relation {relation.value} needs orientations and "
                f"{trajectory.name or 'a trajectory'} has none; use trans_part or "
                "point_distance."
            )
            raise MetricError(msg, option="pose_relation")


def _of_error(rotation: FloatArray, translation: FloatArray, relation: PoseRelation) -> FloatArray:
    """Return the relation's value of the errors (R (N, 3, 3), t (N, 3))."""
    if relation in {PoseRelation.TRANS_PART, PoseRelation.POINT_DISTANCE}:
        return np.asarray(np.linalg.norm(translation, axis=1))
    minus_identity = rotation - np.eye(3)
    if relation is PoseRelation.ROT_PART:
        return np.asarray(np.linalg.norm(minus_identity, axis=(1, 2)))
    if relation is PoseRelation.FULL:
        squares = np.einsum("nij,nij->n", minus_identity, minus_identity)
        return np.asarray(np.sqrt(squares + np.einsum("ni,ni->n", translation, translation)))
    cosine = np.clip((np.trace(rotation, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angles: FloatArray = np.arccos(cosine)
    return np.degrees(angles) if relation is PoseRelation.ANGLE_DEG else angles


def ape_series(reference: Trajectory, aligned: Trajectory, relation: PoseRelation) -> ErrorSeries:
    """Absolute pose error per matched pose, by the pose relation.

    Args:
        reference: matched reference poses Q.
        aligned: matched estimate poses P after the alignment, same stamps.
        relation: what is measured of ``E_i = Q_i^-1 P_i``.

    Raises:
        MetricError: a relation needs orientations that a side lacks.
    """
    _require_orientations(relation, reference, aligned)
    diff = aligned.positions_xyz - reference.positions_xyz
    if relation in {PoseRelation.TRANS_PART, PoseRelation.POINT_DISTANCE}:
        values: FloatArray = np.linalg.norm(diff, axis=1)
        return ErrorSeries(values, reference.stamps_ns, RELATION_UNITS[relation])
    r_q, r_p = _matrices(reference), _matrices(aligned)
    rotation = np.einsum("nji,njk->nik", r_q, r_p)
    translation = np.einsum("nji,nj->ni", r_q, diff)
    values = _of_error(rotation, translation, relation)
    return ErrorSeries(values, reference.stamps_ns, RELATION_UNITS[relation])


def rpe_series(
    reference: Trajectory,
    aligned: Trajectory,
    relation: PoseRelation,
    pairs: tuple[IntArray, IntArray],
) -> ErrorSeries:
    """Relative pose error per pair ``(i, j)``, by the pose relation.

    Args:
        reference: matched reference poses Q.
        aligned: matched estimate poses P after the alignment.
        relation: what is measured of ``E_ij = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``.
        pairs: the index pairs.

    Raises:
        MetricError: no pair, ``point_distance`` (a relative error compares motions, not
            points), or a relation needs orientations that a side lacks.
    """
    i, j = pairs
    if i.size == 0:
        msg = "The RPE delta yields no pair of poses; choose a smaller delta."
        raise MetricError(msg, option="rpe_delta")
    if relation is PoseRelation.POINT_DISTANCE:
        msg = "point_distance compares positions, not motions: use it for APE, not RPE."
        raise MetricError(msg, option="pose_relation")
    stamps = reference.stamps_ns[i]
    q_pos, p_pos = reference.positions_xyz, aligned.positions_xyz
    if reference.quat_xyzw is None or aligned.quat_xyzw is None:
        _require_orientations(relation, reference, aligned)
        diff = (p_pos[j] - p_pos[i]) - (q_pos[j] - q_pos[i])
        return ErrorSeries(np.linalg.norm(diff, axis=1), stamps, RELATION_UNITS[relation])
    r_q, r_p = _matrices(reference), _matrices(aligned)
    # dQ = Q_i^-1 Q_j, dP = P_i^-1 P_j, E = dQ^-1 dP.
    dq_r = np.einsum("nji,njk->nik", r_q[i], r_q[j])
    dp_r = np.einsum("nji,njk->nik", r_p[i], r_p[j])
    dq_t = np.einsum("nji,nj->ni", r_q[i], q_pos[j] - q_pos[i])
    dp_t = np.einsum("nji,nj->ni", r_p[i], p_pos[j] - p_pos[i])
    rotation = np.einsum("nji,njk->nik", dq_r, dp_r)
    translation = np.einsum("nji,nj->ni", dq_r, dp_t - dq_t)
    values = _of_error(rotation, translation, relation)
    return ErrorSeries(values, stamps, RELATION_UNITS[relation])


def _path_axis(trajectory: Trajectory, unit: str) -> FloatArray:
    """Return the cumulative path along a trajectory: metres, or rotation in deg or rad."""
    if unit == "m":
        steps = np.linalg.norm(np.diff(trajectory.positions_xyz, axis=0), axis=1)
    else:
        if trajectory.quat_xyzw is None:
            msg = "An RPE delta in degrees or radians needs orientations; count frames or metres."
            raise MetricError(msg, option="rpe_unit")
        rotations = Rotation.from_quat(trajectory.quat_xyzw)
        steps = (rotations[:-1].inv() * rotations[1:]).magnitude()
        if unit == "d":
            steps = np.degrees(steps)
    out: FloatArray = np.concatenate([[0.0], np.cumsum(steps)])
    return out


_PAIR_BLOCK = 512
"""Start poses compared at once by :func:`_angle_pairs` (a block of 512 x N angles)."""


def _angle_pairs(
    trajectory: Trajectory, *, delta_rad: float, tolerance: float
) -> tuple[IntArray, IntArray]:
    """Every pair ``i < j`` whose relative rotation angle is within ``tolerance`` of delta.

    The angles are computed a block of start poses at a time (memory: 512 x N).
    """
    if trajectory.quat_xyzw is None:
        msg = "An RPE delta in degrees or radians needs orientations; count frames or metres."
        raise MetricError(msg, option="rpe_unit")
    quats = trajectory.quat_xyzw / np.linalg.norm(trajectory.quat_xyzw, axis=1, keepdims=True)
    n = len(quats)
    starts: list[IntArray] = []
    ends: list[IntArray] = []
    for first in range(0, n, _PAIR_BLOCK):  # one turn per block of 512 poses
        block = quats[first : first + _PAIR_BLOCK]
        cosines = np.clip(np.abs(block @ quats.T), 0.0, 1.0)
        angles = 2.0 * np.arccos(cosines)
        later = np.arange(n)[None, :] > np.arange(first, first + len(block))[:, None]
        i, j = np.nonzero(later & (np.abs(angles - delta_rad) <= tolerance * delta_rad))
        starts.append(i + first)
        ends.append(j)
    return np.concatenate(starts).astype(np.intp), np.concatenate(ends).astype(np.intp)


def evo_pairs(
    reference: Trajectory,
    estimate: Trajectory,
    *,
    delta: float,
    unit: str,
    all_pairs: bool = False,
    tolerance: float = 0.1,
    from_reference: bool = False,
) -> tuple[IntArray, IntArray]:
    """The RPE index pairs as evo's ``--delta``/``--delta_unit``/``--all_pairs`` choose them.

    ``f``: ``j = i + delta`` frames. ``m``, ``d``, ``r``: ``j`` is the first pose at least
    ``delta`` metres, degrees or radians of motion after ``i``, measured along the
    *estimate* as evo does. Without ``all_pairs`` each pair starts where the last ended.
    With it (as evo 1.38 was observed to choose them): frames, every ``i``; metres, for
    each ``i`` the first ``j`` whose path is at least ``delta (1 - tolerance)`` if it is
    at most ``delta (1 + tolerance)``; degrees and radians, every ``i < j`` whose direct
    relative rotation angle is within ``tolerance * delta`` of ``delta``.

    Args:
        reference: the matched reference poses (only their number is used).
        estimate: the matched, aligned estimate poses.
        delta: the step.
        unit: ``f``, ``m``, ``d`` or ``r``.
        all_pairs: every pose starts a pair whose path is within ``tolerance`` (relative)
            of ``delta``.
        tolerance: the relative tolerance of ``all_pairs`` pairs.
        from_reference: measure the path along the reference instead.

    Raises:
        MetricError: a delta that is not positive, or not whole for frames.
    """
    n = len(reference)
    if not (np.isfinite(delta) and delta > 0):
        msg = f"The RPE delta must be positive, got {delta!r}."
        raise MetricError(msg, option="rpe_delta")
    if unit == "f":
        if delta != int(delta):
            msg = f"An RPE delta in frames must be a whole number, got {delta!r}."
            raise MetricError(msg, option="rpe_delta")
        step = int(delta)
        starts = np.arange(0, max(n - step, 0), 1 if all_pairs else step)
        return starts, starts + step
    axis = _path_axis(reference if from_reference else estimate, unit)
    reach = np.searchsorted(axis, axis + delta, side="left")
    reach = np.maximum(reach, np.arange(1, n + 1))
    if all_pairs and unit == "m":  # per start, the pose whose path is nearest delta
        low = np.maximum(np.searchsorted(axis, axis + delta, side="left"), np.arange(1, n + 1))
        below = np.minimum(np.maximum(low - 1, np.arange(1, n + 1)), n - 1)
        above = np.minimum(low, n - 1)
        pick_below = np.abs(axis[below] - axis - delta) <= np.abs(axis[above] - axis - delta)
        ends = np.where(pick_below, below, above)
        starts = np.arange(n)
        close = (ends > starts) & (np.abs(axis[ends] - axis - delta) <= delta * tolerance)
        return starts[close], ends[close]
    if all_pairs:  # every pair whose relative rotation is within the tolerance
        return _angle_pairs(
            reference if from_reference else estimate,
            delta_rad=np.radians(delta) if unit == "d" else delta,
            tolerance=tolerance,
        )
    firsts: list[int] = []
    i = 0
    reach_list = reach.tolist()
    while i < n and reach_list[i] < n:  # once per segment, not per pose
        firsts.append(i)
        i = reach_list[i]
    starts = np.asarray(firsts, dtype=np.intp)
    return starts, reach[starts]


def scale_only(reference: Trajectory, estimate: Trajectory, *, poses: int | None) -> Trajectory:
    """Return the matched estimate scaled about its frame's origin (evo's ``-s`` without ``-a``).

    The scale is Umeyama's Sim(3) scale of the first ``poses`` matched poses (all: None);
    the rotation and translation found with it are not applied.

    Args:
        reference: the matched reference poses.
        estimate: the matched estimate poses, pose by pose with ``reference``.
        poses: how many leading poses estimate the scale (None: all).
    """
    n = len(estimate) if poses is None else min(poses, len(estimate))
    found = align_umeyama(estimate.positions_xyz[:n], reference.positions_xyz[:n], with_scale=True)
    return estimate.transformed(SimilarityTransform(np.eye(3), np.zeros(3), found.scale))
