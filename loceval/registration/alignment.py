"""Alignment in space: the transform that maps the estimate's frame onto the reference's.

Methods:
- ``se3`` / ``sim3``: Umeyama's closed form (Umeyama 1991, "Least-squares estimation of
  transformation parameters between two point patterns", eqs. 34-42), without / with scale.
- ``yaw``: 4-DoF, translation and a rotation about gravity (z) only, for VIO whose roll and
  pitch are observable: the planar Umeyama problem on the centred x-y coordinates.
- ``origin``: the first matched poses coincide (full pose when both carry orientations,
  positions only otherwise).
- ``calibrate``: the framework paper's calibration (§3.3.3, Fig. 4): ``T_C = Q_k · P_k^-1``
  from one synchronized sample ``k`` (the first by default, or the one nearest a given
  time), so that ``P'_n = T_C · P_n``.
- ``none``: identity.

``se3``, ``sim3`` and ``yaw`` may be estimated from the first N poses or seconds only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import FloatArray, StampsNs
from loceval.core.geometry import SimilarityTransform
from loceval.errors import AlignmentError
from loceval.options import AlignMethod
from loceval.trajectory import MAX_SPAN_S, Trajectory

__all__ = [
    "AlignMethod",
    "AlignWindow",
    "Alignment",
    "align",
    "align_calibrate",
    "align_origin",
    "align_umeyama",
    "align_yaw",
]

_NS_PER_S = 1_000_000_000
_RANK_TOLERANCE = 1e-9
"""Relative size below which a singular value of the cross-covariance counts as zero."""


@dataclass(frozen=True, slots=True)
class AlignWindow:
    """The leading part of the matched poses used to estimate the transform.

    Exactly one of ``poses`` and ``seconds`` is set, or neither (all poses).
    """

    poses: int | None = None
    seconds: float | None = None

    @classmethod
    def parse(cls, text: str | None) -> AlignWindow:
        """Parse ``"N"`` (poses) or ``"Ns"`` (seconds); None or empty means all poses.

        Raises:
            AlignmentError: the text is neither.
        """
        if not text:
            return cls()
        raw = text.strip()
        try:
            if raw.endswith("s"):
                seconds = float(raw[:-1])
                if not np.isfinite(seconds) or not 0 < seconds <= MAX_SPAN_S:
                    raise ValueError(raw)  # noqa: TRY301  (one message for every bad value)
                return cls(seconds=seconds)
            poses = int(raw)
        except ValueError:
            msg = (
                f"The alignment window takes a number of poses or seconds like 100 or 5s, "
                f"got {text!r}."
            )
            raise AlignmentError(msg, option="align_first") from None
        if poses < 1:
            msg = f"The alignment window needs at least one pose, got {text!r}."
            raise AlignmentError(msg, option="align_first")
        return cls(poses=poses)

    def __str__(self) -> str:
        """Return the CLI spelling."""
        if self.poses is not None:
            return str(self.poses)
        if self.seconds is not None:
            return f"{self.seconds:g}s"
        return "all"

    def count(self, stamps_ns: StampsNs) -> int:
        """Return how many leading poses of ``stamps_ns`` the window holds."""
        n = len(stamps_ns)
        if self.poses is not None:
            return min(self.poses, n)
        if self.seconds is not None:
            end = stamps_ns[0] + round(self.seconds * _NS_PER_S)
            return int(np.searchsorted(stamps_ns, end, side="right"))
        return n


@dataclass(frozen=True, slots=True)
class Alignment:
    """The transform found and how.

    Attributes:
        method: the alignment method.
        transform: maps estimate-frame points to the reference frame.
        poses_used: how many matched poses estimated it.
        window: the leading window used.
        warnings: anything the caller should report (e.g. a window ignored).
    """

    method: AlignMethod
    transform: SimilarityTransform
    poses_used: int
    window: AlignWindow
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """Return ``{"method", "rotation", "translation", "scale", "poses_used", "window"}``."""
        return {
            "method": self.method.value,
            **self.transform.to_dict(),
            "poses_used": self.poses_used,
            "window": str(self.window),
        }


def align(
    reference: Trajectory,
    estimate: Trajectory,
    *,
    method: AlignMethod = AlignMethod.SE3,
    window: AlignWindow | None = None,
    calibrate_at_s: float | None = None,
) -> Alignment:
    """Find the transform that maps ``estimate`` onto ``reference``.

    The two trajectories are matched pose by pose (see
    :func:`loceval.registration.association.associate`).

    Args:
        reference: matched reference poses.
        estimate: matched estimate poses, same length.
        method: the alignment method.
        window: leading window for ``se3``, ``sim3`` and ``yaw``.
        calibrate_at_s: for ``calibrate``, seconds after the first matched pose at which
            to take the calibration sample (the first by default).

    Returns:
        The alignment.

    Raises:
        AlignmentError: too few poses, degenerate geometry, or missing orientations.
    """
    window = window or AlignWindow()
    if len(reference) != len(estimate):
        msg = f"Alignment needs matched poses, got {len(reference)} and {len(estimate)}."
        raise AlignmentError(msg)
    notes: list[str] = []
    if method in {AlignMethod.ORIGIN, AlignMethod.CALIBRATE, AlignMethod.NONE} and (
        window.poses is not None or window.seconds is not None
    ):
        notes.append(
            f"The alignment window ({window}) is ignored by the alignment method '{method.value}'."
        )
        window = AlignWindow()
    if method is AlignMethod.CALIBRATE:
        index = _calibration_index(estimate, calibrate_at_s)
        transform = align_calibrate(reference, estimate, index=index)
        return Alignment(method, transform, 1, window, tuple(notes))
    if calibrate_at_s is not None:
        notes.append(
            "The calibration time is only used by the alignment method 'calibrate'; ignored."
        )
    if method is AlignMethod.NONE:
        return Alignment(method, SimilarityTransform.identity(), 0, window, tuple(notes))
    if method is AlignMethod.ORIGIN:
        return Alignment(method, align_origin(reference, estimate), 1, window, tuple(notes))
    n = window.count(estimate.stamps_ns)
    src = estimate.positions_xyz[:n]
    dst = reference.positions_xyz[:n]
    if method is AlignMethod.YAW:
        transform = align_yaw(src, dst)
    else:
        transform = align_umeyama(src, dst, with_scale=method is AlignMethod.SIM3)
    return Alignment(method, transform, n, window, tuple(notes))


def align_umeyama(
    src_xyz: FloatArray, dst_xyz: FloatArray, *, with_scale: bool = False
) -> SimilarityTransform:
    """Least-squares similarity (or rigid) transform mapping ``src`` onto ``dst`` (Umeyama).

    Args:
        src_xyz: (N, 3) points in the estimate's frame.
        dst_xyz: (N, 3) matching points in the reference frame.
        with_scale: estimate the scale too (Sim3) instead of fixing it to 1 (SE3).

    Returns:
        ``T`` minimizing ``sum ||dst_i - T(src_i)||²``.

    Raises:
        AlignmentError: fewer than three points, or points so close to a line (or, with
            scale, a single point) that the rotation is undetermined.
    """
    n = src_xyz.shape[0]
    if n < 3:
        msg = (
            f"Umeyama alignment needs at least 3 matched poses, got {n}; use the alignment "
            "method 'origin'."
        )
        raise AlignmentError(msg, option="align")
    mu_src = src_xyz.mean(axis=0)
    mu_dst = dst_xyz.mean(axis=0)
    src_c = src_xyz - mu_src
    dst_c = dst_xyz - mu_dst
    sigma2_src = float((src_c**2).sum() / n)  # eq. 36
    cov = dst_c.T @ src_c / n  # eq. 38
    U, d, Vt = np.linalg.svd(cov)
    if d[0] <= 0.0 or d[1] <= _RANK_TOLERANCE * d[0]:
        msg = (
            f"The {n} matched positions lie on a line (or a point), so the rotation about "
            "it is undetermined; use a path that turns, or the alignment method 'yaw', "
            "'origin' or 'calibrate'."
        )
        raise AlignmentError(msg, option="align")
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:  # eq. 39: reflection guard
        S[2, 2] = -1.0
    rotation = U @ S @ Vt  # eq. 40
    scale = float(np.trace(np.diag(d) @ S) / sigma2_src) if with_scale else 1.0  # eq. 42
    translation = mu_dst - scale * rotation @ mu_src  # eq. 41
    return SimilarityTransform(rotation, translation, scale)


def align_yaw(src_xyz: FloatArray, dst_xyz: FloatArray) -> SimilarityTransform:
    """Least-squares translation + rotation about z mapping ``src`` onto ``dst`` (4-DoF).

    Args:
        src_xyz: (N, 3) points in the estimate's frame (gravity along -z).
        dst_xyz: (N, 3) matching points in the reference frame.

    Returns:
        The rigid transform with a z-only rotation.

    Raises:
        AlignmentError: fewer than two points, or no horizontal extent to fix the yaw.
    """
    n = src_xyz.shape[0]
    if n < 2:
        msg = (
            f"Yaw alignment needs at least 2 matched poses, got {n}; use the alignment method "
            "'origin'."
        )
        raise AlignmentError(msg, option="align")
    mu_src = src_xyz.mean(axis=0)
    mu_dst = dst_xyz.mean(axis=0)
    a = src_xyz[:, :2] - mu_src[:2]
    b = dst_xyz[:, :2] - mu_dst[:2]
    # Minimizing sum ||b - R(θ) a||² gives θ = atan2(Σ a×b, Σ a·b).
    cross = float((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())
    dot = float((a * b).sum())
    if np.hypot(cross, dot) <= _RANK_TOLERANCE * max(float((a**2).sum()), 1e-300):
        msg = (
            "The matched positions have no horizontal extent, so the yaw is undetermined; "
            "use the alignment method 'origin' or 'calibrate'."
        )
        raise AlignmentError(msg, option="align")
    theta = np.arctan2(cross, dot)
    c, s = np.cos(theta), np.sin(theta)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return SimilarityTransform(rotation, mu_dst - rotation @ mu_src, 1.0)


def align_origin(reference: Trajectory, estimate: Trajectory) -> SimilarityTransform:
    """Make the first matched poses coincide.

    With orientations on both sides this is the full pose ``Q_0 · P_0^-1``; otherwise the
    positions only (a translation).
    """
    if reference.quat_xyzw is not None and estimate.quat_xyzw is not None:
        return align_calibrate(reference, estimate, index=0)
    return SimilarityTransform(
        np.eye(3), reference.positions_xyz[0] - estimate.positions_xyz[0], 1.0
    )


def align_calibrate(
    reference: Trajectory, estimate: Trajectory, *, index: int = 0
) -> SimilarityTransform:
    """The framework paper's calibration ``T_C = Q_k · P_k^-1`` at matched sample ``k``.

    Raises:
        AlignmentError: either side has no orientations.
    """
    if reference.quat_xyzw is None or estimate.quat_xyzw is None:
        side = "reference" if reference.quat_xyzw is None else "estimate"
        msg = (
            f"The alignment method 'calibrate' needs orientations, but the {side} is "
            "position-only; use the alignment method 'origin', 'se3' or 'yaw'."
        )
        raise AlignmentError(msg, option="align")
    Q = SimilarityTransform.from_pose(reference.positions_xyz[index], reference.quat_xyzw[index])
    P = SimilarityTransform.from_pose(estimate.positions_xyz[index], estimate.quat_xyzw[index])
    return Q.compose(P.inverse())


def _calibration_index(estimate: Trajectory, calibrate_at_s: float | None) -> int:
    if calibrate_at_s is None:
        return 0
    if not np.isfinite(calibrate_at_s) or calibrate_at_s < 0:
        msg = (
            f"The calibration time takes seconds after the first matched pose, got "
            f"{calibrate_at_s!r}."
        )
        raise AlignmentError(msg, option="calibrate_at_s")
    target = estimate.stamps_ns[0] + round(calibrate_at_s * _NS_PER_S)
    if target > estimate.stamps_ns[-1]:
        msg = (
            f"The calibration time {calibrate_at_s:g} s is after the last matched pose "
            f"({estimate.duration_s:.3f} s after the first); choose an earlier time."
        )
        raise AlignmentError(msg, option="calibrate_at_s")
    i = int(np.searchsorted(estimate.stamps_ns, target))
    if i > 0 and target - estimate.stamps_ns[i - 1] <= estimate.stamps_ns[i] - target:
        i -= 1
    return i
