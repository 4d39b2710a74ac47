"""The device (hand-eye) offset from the motion, estimated together with the time offset.

The device offset is the fixed transform from the reference's tracked body to the estimated
sensor. The framework paper (§3.3.2) has the user measure this offset by hand into a URDF. Here it
comes from the data: between two stamps about a second apart, the body moves by ``A``
(reference) and the sensor by ``B`` (estimate), and ``A X = X B`` for the offset ``X``
(``T_world_sensor = T_world_body · X``, what :meth:`Trajectory.with_body_offset` applies).
Relative motions over short windows are what SLAM drift cannot spoil: a rigid alignment of
the whole run would push the drift into the offset.

1. Closed form: the rotation from the rotation axes (Park and Martin 1994: ``alpha = R_X
   beta``, an orthogonal Procrustes problem), then the translation (and the monocular scale)
   by linear least squares on ``(R_A - I) t_X = s R_X t_B - t_A``.
2. Robust Gauss-Newton (Huber weights) over all pairs, jointly with the time offset.
3. A 1-sigma per component from the sandwich covariance (pairs share no pose, so their
   residuals are nearly independent) times the measured safety factor ``SIGMA_SAFETY``.

**Observability.** The translation along a direction is observable only when the body rotates
about axes across it: the small eigenvalues of ``mean((R_A - I)^T (R_A - I))`` give the
directions it cannot tell (a ground robot turning about z cannot tell the offset's z). The
rotation about an axis is unobservable when every rotation is about that axis: the small
eigenvalues of ``mean(|a|² I - a a^T)`` over the rotation vectors ``a``. Components along the
body's axes are named ``"x"``, ``"y"``, ``"z"`` (translation) and ``"rx"``, ``"ry"``,
``"rz"`` (rotation about the tracked body's x, y, z axes). They are listed in
``unobservable``, not applied (0 in the translation; no rotation about that axis) and have
no sigma.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.calibration.common import (
    NS_PER_S,
    FitOptions,
    PoseSampler,
    fit_relative_motions,
    initial_rotation,
    make_pairs,
    relative_motions,
    rotation_excitation,
    rotvec_of,
    weak_axes,
)
from loceval.core.arrays import FloatArray
from loceval.core.geometry import SimilarityTransform
from loceval.errors import AssociationError, InputError
from loceval.registration.association import DEFAULT_MAX_GAP_NS
from loceval.trajectory import Trajectory

__all__ = [
    "ROTATION_AXES",
    "TRANSLATION_AXES",
    "DeviceOffsetComparison",
    "DeviceOffsetEstimate",
    "DeviceOffsetSource",
    "compare_device_offset",
    "estimate_device_offset",
]

TRANSLATION_AXES = ("x", "y", "z")
ROTATION_AXES = ("rx", "ry", "rz")
WEAK_EXCITATION = 1e-3
"""An eigenvalue of the excitation below this share of the largest is unobservable."""
MIN_ROTATION_DEG = 1.0
"""Windows must rotate the body by this much on average for any device offset."""
MIN_TRAVEL_M = 0.01
"""RMS travel per window across the only rotation axis that tells the rotation about it."""
_MIN_PAIRS = 20
# For each body axis: an Euler sequence that puts a rotation about it first (leftmost).
_EULER_FIRST: tuple[Literal["XYZ"], Literal["YZX"], Literal["ZXY"]] = ("XYZ", "YZX", "ZXY")


class DeviceOffsetSource(StrEnum):
    """Where a device offset comes from."""

    GIVEN = "given"
    URDF = "urdf"
    ESTIMATED = "estimated"


@dataclass(frozen=True, slots=True)
class DeviceOffsetEstimate:
    """The body -> sensor offset found in the data, with 1-sigmas.

    Attributes:
        translation_m: (x, y, z) of the sensor in the tracked body's frame, metres (0 for
            an unobservable component).
        rotation_xyzw: the sensor's orientation in the body's frame (x y z w).
        sigma_translation_m: 1-sigma per axis, metres (None where unobservable).
        sigma_rotation_deg: 1-sigma of the rotation about the body's x, y, z axes, degrees
            (None where unobservable).
        source: always ``estimated`` here.
        unobservable: components the motion does not excite (``"x"``... ``"rz"``).
        time_offset_s: the time offset estimated jointly (added to the estimate's stamps).
        sigma_time_offset_s: its 1-sigma (None when it was held fixed).
        scale: metres per estimate unit (1 unless estimated for a monocular estimate).
        pairs: relative motions used.
        rms_rotation_deg: RMS rotation residual of the fit, degrees.
        rms_translation_m: RMS translation residual of the fit, metres.
        warnings: sentences for the user.
    """

    translation_m: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]
    sigma_translation_m: tuple[float | None, float | None, float | None]
    sigma_rotation_deg: tuple[float | None, float | None, float | None]
    source: DeviceOffsetSource
    unobservable: tuple[str, ...]
    time_offset_s: float
    sigma_time_offset_s: float | None
    scale: float
    pairs: int
    rms_rotation_deg: float
    rms_translation_m: float
    warnings: tuple[str, ...] = ()

    @property
    def transform(self) -> SimilarityTransform:
        """The offset as a rigid transform (body -> sensor), for ``with_body_offset``."""
        rotation = Rotation.from_quat(np.array(self.rotation_xyzw)).as_matrix()
        return SimilarityTransform(rotation, np.array(self.translation_m), 1.0)

    def to_dict(self) -> dict[str, object]:
        """Return the contract's ``device_offset`` object."""
        return {
            "translation_m": list(self.translation_m),
            "rotation_xyzw": list(self.rotation_xyzw),
            "sigma_translation_m": list(self.sigma_translation_m),
            "sigma_rotation_deg": list(self.sigma_rotation_deg),
            "source": self.source.value,
            "unobservable": list(self.unobservable),
        }


def estimate_device_offset(
    reference: Trajectory,
    estimate: Trajectory,
    *,
    time_offset_s: float,
    fit_time_offset: bool = True,
    with_scale: bool = False,
    max_gap_s: float = DEFAULT_MAX_GAP_NS / NS_PER_S,
    window_s: float = 1.0,
    max_pairs: int = 3_000,
) -> DeviceOffsetEstimate:
    """Estimate the tracked body -> sensor offset, jointly with the time offset.

    Args:
        reference: the tracked body's poses (ground truth).
        estimate: the sensor's poses in the estimate's own (possibly drifting) frame.
        time_offset_s: the time offset to start from (from
            :func:`loceval.calibration.clock.estimate_time_offset`, or given), seconds.
        fit_time_offset: refine the time offset jointly (else hold it fixed).
        with_scale: estimate the estimate's scale too (monocular SLAM).
        max_gap_s: longest interval between reference poses that is not a tracking loss.
        window_s: length of the relative motions, seconds (long enough to rotate, short
            enough that drift stays small: about a second).
        max_pairs: most relative motions used (thinned evenly beyond it).

    Returns:
        The offset with its 1-sigmas and the unobservable components.

    Raises:
        InputError: either side has no orientations, or the body hardly rotates.
        AssociationError: too few stretches of the estimate lie on tracked reference.
    """
    if reference.quat_xyzw is None or estimate.quat_xyzw is None:
        side = reference.name if reference.quat_xyzw is None else estimate.name
        msg = (
            f"Trajectory {side!r} has no orientations, so the device offset cannot be "
            "estimated (a position-only system gets the time offset only); give the offset "
            "or record orientations."
        )
        raise InputError(msg, option="device")
    if not (np.isfinite(window_s) and window_s > 0):
        msg = f"The relative-motion window must be positive seconds, got {window_s!r}."
        raise InputError(msg, option="device")
    if not (np.isfinite(max_gap_s) and max_gap_s > 0):
        msg = f"The longest bridged interval must be positive seconds, got {max_gap_s!r}."
        raise InputError(msg, option="max_gap_s")
    max_gap_ns = round(max_gap_s * NS_PER_S)
    sampler = PoseSampler.from_start(reference, max_gap_ns=max_gap_ns)
    offset_ns = round(time_offset_s * NS_PER_S)
    pairs = make_pairs(
        estimate,
        sampler,
        offset_ns=offset_ns,
        window_s=window_s,
        margin_s=0.05,
        max_pairs=max_pairs,
    )
    if pairs.i.shape[0] < _MIN_PAIRS:
        msg = (
            f"Only {pairs.i.shape[0]} one-second stretches of {estimate.name!r} lie on "
            f"tracked parts of {reference.name!r} at the time offset {time_offset_s:g} s; "
            "check the time offset or record a longer overlap."
        )
        raise AssociationError(msg, option="device")
    t_s = (estimate.stamps_ns - sampler.origin_ns + offset_ns).astype(np.float64) / NS_PER_S
    both = np.concatenate((pairs.i, pairs.j))
    p_ref = np.zeros((len(estimate), 3))
    q_ref = np.tile([0.0, 0.0, 0.0, 1.0], (len(estimate), 1))
    p_ref[both] = sampler.positions_at(t_s[both])
    q_ref[both] = sampler.quat_at(t_s[both])
    a_q, a_t = relative_motions(p_ref, q_ref, pairs.i, pairs.j)
    _, b_t = relative_motions(estimate.positions_xyz, estimate.quat_xyzw, pairs.i, pairs.j)
    alpha = rotvec_of(a_q)
    mean_angle_deg = float(np.degrees(np.linalg.norm(alpha, axis=1).mean()))
    if mean_angle_deg < MIN_ROTATION_DEG:
        msg = (
            f"The tracked body of {reference.name!r} turns by {mean_angle_deg:.2f} deg per "
            f"{window_s:g} s on average, too little to tell the device offset; record a run "
            "that turns about several axes, or give the offset."
        )
        raise InputError(msg, option="device")
    rot_weak = weak_axes(rotation_excitation(alpha), threshold=WEAK_EXCITATION)
    rot_a = Rotation.from_quat(a_q).as_matrix()
    trans_weak = weak_axes(_translation_excitation(rot_a), threshold=WEAK_EXCITATION)
    rotation0 = initial_rotation(sampler, estimate, pairs.i, pairs.j, offset_ns=offset_ns)
    free = [k not in trans_weak for k in range(3)]
    if len(rot_weak) == 1 and _moves_across(b_t @ rotation0.T, rot_weak[0]):
        # Every rotation is about one axis (a ground robot), so the rotation axes cannot
        # tell the rotation about it; the direction of travel can (the sensor's travel
        # seen from the body), when the body moves across that axis.
        rotation0 = _rotation_from_travel(
            rot_a, a_t, b_t, rotation0, rot_weak[0], free=free, with_scale=with_scale
        )
        rot_weak = []
    for k in rot_weak:
        rotation0 = _drop_rotation_about(rotation0, k)
    translation0, scale0 = _initial_translation(
        rot_a, a_t, b_t, rotation0, free=free, with_scale=with_scale
    )
    options = FitOptions(
        fit_offset=fit_time_offset,
        fit_translation=True,
        fit_scale=with_scale,
        fixed_rotation_axes=tuple(rot_weak),
        fixed_translation_axes=tuple(trans_weak),
    )
    fit = fit_relative_motions(
        sampler,
        estimate,
        pairs,
        offset_ns=offset_ns,
        rotation0=rotation0,
        translation0=translation0,
        scale0=scale0,
        options=options,
    )
    sd = np.sqrt(np.diag(fit.cov))
    unobservable = tuple(
        [TRANSLATION_AXES[k] for k in trans_weak] + [ROTATION_AXES[k] for k in rot_weak]
    )
    notes: list[str] = []
    if unobservable:
        notes.append(
            f"The motion does not excite the device offset's {', '.join(unobservable)} "
            "(it would need rotation about other axes), so they are not estimated and not "
            "applied; give them from a drawing or a URDF if they matter."
        )
    translation = tuple(0.0 if k in trans_weak else float(fit.translation_m[k]) for k in range(3))
    return DeviceOffsetEstimate(
        translation_m=_triple(translation),
        rotation_xyzw=_quad(Rotation.from_matrix(fit.rotation).as_quat()),
        sigma_translation_m=_sigmas(sd[4:7], trans_weak, 1.0),
        sigma_rotation_deg=_sigmas(sd[1:4], rot_weak, float(np.degrees(1.0))),
        source=DeviceOffsetSource.ESTIMATED,
        unobservable=unobservable,
        time_offset_s=offset_ns / NS_PER_S + fit.offset_s,
        sigma_time_offset_s=float(sd[0]) if fit_time_offset else None,
        scale=fit.scale,
        pairs=fit.pairs,
        rms_rotation_deg=float(np.degrees(fit.rms_rotation_rad)),
        rms_translation_m=fit.rms_translation_m,
        warnings=tuple(notes),
    )


@dataclass(frozen=True, slots=True)
class DeviceOffsetComparison:
    """How far an estimated device offset is from a given one (URDF, ``/tf_static``).

    Attributes:
        translation_difference_m: distance over the observable axes, metres.
        rotation_difference_deg: angle of the rotation between them (about observable
            axes), degrees.
        consistent: every observable component differs by at most 3 sigma.
        message: one sentence for the report.
    """

    translation_difference_m: float
    rotation_difference_deg: float
    consistent: bool
    message: str


def compare_device_offset(
    estimated: DeviceOffsetEstimate, given: SimilarityTransform, *, given_source: str = "URDF"
) -> DeviceOffsetComparison:
    """Compare an estimated offset with a given one, component by component.

    Args:
        estimated: from :func:`estimate_device_offset`.
        given: the offset from a URDF, ``/tf_static`` or a measurement (body -> sensor).
        given_source: how the message names the given offset.

    Returns:
        The differences (translation in metres, rotation in degrees) and whether they lie
        within 3 sigma.
    """
    d_t = np.array(estimated.translation_m) - np.array(given.translation)
    r_est = Rotation.from_quat(np.array(estimated.rotation_xyzw))
    # Left perturbation: the rotation about the tracked body's axes that maps given to found.
    d_r = (r_est * Rotation.from_matrix(np.array(given.rotation)).inv()).as_rotvec()
    within = True
    for k in range(3):
        sig_t = estimated.sigma_translation_m[k]
        sig_r = estimated.sigma_rotation_deg[k]
        if sig_t is None:
            d_t[k] = 0.0
        else:
            within &= abs(d_t[k]) <= 3.0 * sig_t
        if sig_r is None:
            d_r[k] = 0.0
        else:
            within &= abs(np.degrees(d_r[k])) <= 3.0 * sig_r
    dist_m = float(np.linalg.norm(d_t))
    angle_deg = float(np.degrees(np.linalg.norm(d_r)))
    verdict = (
        "within 3 sigma, so the two agree"
        if within
        else f"beyond 3 sigma: check the {given_source} (frame, sign, units) or the tracking"
    )
    skipped = (
        f" (not compared: {', '.join(estimated.unobservable)})" if estimated.unobservable else ""
    )
    message = (
        f"The device offset estimated from the motion differs from the {given_source} by "
        f"{dist_m * 1e3:.1f} mm and {angle_deg:.2f} deg{skipped}, {verdict}."
    )
    return DeviceOffsetComparison(dist_m, angle_deg, bool(within), message)


def _translation_excitation(rot_a: FloatArray) -> FloatArray:
    """``mean((R_A - I)^T (R_A - I))``: the information on the translation."""
    d = rot_a - np.eye(3)
    out: FloatArray = np.einsum("nki,nkj->ij", d, d) / rot_a.shape[0]
    return out


def _moves_across(travel_body: FloatArray, axis: int) -> bool:
    """Whether the windows' travel (body frame) has an RMS of MIN_TRAVEL_M across ``axis``."""
    across = np.delete(travel_body, axis, axis=1)
    return bool(np.sqrt((across**2).sum(axis=1).mean()) >= MIN_TRAVEL_M)


def _rotation_from_travel(
    rot_a: FloatArray,
    a_t: FloatArray,
    b_t: FloatArray,
    rotation: FloatArray,
    axis: int,
    *,
    free: list[bool],
    with_scale: bool,
) -> FloatArray:
    """The rotation about body ``axis`` that makes the travel agree, by linear least squares.

    With ``w = R' t_B`` and ``R_u(g) w = w_par + cos g w_perp + sin g (u x w)``,
    ``(R_A - I) t_X - s R_u(g) w = -t_A`` is linear in ``t_X``, ``s``, ``s cos g`` and
    ``s sin g`` (``s`` = 1 without scale).
    """
    n = rot_a.shape[0]
    u = np.eye(3)[axis]
    w = b_t @ rotation.T
    w_par = np.outer(w @ u, u)
    w_perp = w - w_par
    w_cross = np.cross(u, w)
    cols = [(rot_a - np.eye(3))[:, :, np.array(free)], -w_perp[:, :, None], -w_cross[:, :, None]]
    rhs = -a_t
    if with_scale:
        cols.append(-w_par[:, :, None])
    else:
        rhs = rhs + w_par
    lhs = np.concatenate(cols, axis=2).reshape(3 * n, -1)
    sol = np.linalg.lstsq(lhs, rhs.reshape(-1), rcond=None)[0]
    k = int(sum(free))
    angle = float(np.arctan2(sol[k + 1], sol[k]))
    out: FloatArray = Rotation.from_rotvec(angle * u).as_matrix() @ rotation
    return out


def _drop_rotation_about(rotation: FloatArray, axis: int) -> FloatArray:
    """Remove the leading rotation about a body axis (``R = R_axis(g) · R'`` -> ``R'``)."""
    seq = _EULER_FIRST[axis]
    angles = Rotation.from_matrix(rotation).as_euler(seq)
    angles[0] = 0.0
    out: FloatArray = Rotation.from_euler(seq, angles).as_matrix()
    return out


def _initial_translation(
    rot_a: FloatArray,
    a_t: FloatArray,
    b_t: FloatArray,
    rotation: FloatArray,
    *,
    free: list[bool],
    with_scale: bool,
) -> tuple[FloatArray, float]:
    """Linear least squares of ``(R_A - I) t_X - s R_X t_B = -t_A`` over the free axes."""
    n = rot_a.shape[0]
    lhs = (rot_a - np.eye(3))[:, :, np.array(free)]
    rb = b_t @ rotation.T
    if with_scale:
        lhs = np.concatenate((lhs, -rb[:, :, None]), axis=2)
        rhs = -a_t
    else:
        rhs = rb - a_t
    sol = np.linalg.lstsq(lhs.reshape(3 * n, -1), rhs.reshape(-1), rcond=None)[0]
    translation = np.zeros(3)
    translation[np.array(free)] = sol[: int(sum(free))]
    scale = float(sol[-1]) if with_scale else 1.0
    if not (np.isfinite(scale) and scale > 0):
        msg = (
            f"The estimate's scale came out as {scale!r}; the estimate does not move like the "
            "reference, check the time offset and the trajectories."
        )
        raise InputError(msg, option="device")
    return translation, scale


def _sigmas(
    sd: FloatArray, weak: list[int], factor: float
) -> tuple[float | None, float | None, float | None]:
    out = [None if k in weak else float(sd[k] * factor) for k in range(3)]
    return out[0], out[1], out[2]


def _triple(values: tuple[float, ...]) -> tuple[float, float, float]:
    return float(values[0]), float(values[1]), float(values[2])


def _quad(values: FloatArray) -> tuple[float, float, float, float]:
    return float(values[0]), float(values[1]), float(values[2]), float(values[3])
