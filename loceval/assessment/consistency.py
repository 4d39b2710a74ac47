"""Can a system's own reported uncertainty be trusted? NEES against the ground truth.

AMCL (``PoseWithCovarianceStamped``), odometry (``Odometry``) and UWB systems publish a
covariance with each pose. If it is honest, the normalised estimation error squared
``NEES = eᵀ S⁻¹ e`` of the aligned error ``e`` is chi-square distributed with ``dof``
degrees of freedom, so its mean over N poses is close to ``dof`` (Bar-Shalom, Li &
Kirubarajan 2001, "Estimation with Applications to Tracking and Navigation", §5.4.2).

- **Band of the mean.** For N independent poses, ``N · mean`` is chi-square with ``N dof``
  degrees, so the 95 % band of the mean is ``chi2.ppf([0.025, 0.975], N dof) / N``. Errors
  along a trajectory are autocorrelated, and then this band is far too narrow: the mean
  of N correlated NEES values varies like that of ``N_eff`` independent ones. We therefore
  use ``N_eff`` (the effective sample size of the NEES series, Sokal's windowed
  autocorrelation time, :func:`loceval.assessment.uncertainty.n_effective`) in place of N:
  ``chi2.ppf([0.025, 0.975], N_eff dof) / N_eff``, which matches the mean's expectation
  ``dof`` and its variance ``2 dof / N_eff``. The band for independent poses is kept as
  ``band95_independent`` for comparison with tools that assume it.
- **Verdict.** consistent (mean inside the band), conservative (below: the covariance is
  larger than the errors), overconfident (above: the covariance is too small).
- **Planar systems** (AMCL) report zero (or a constant placeholder) z variance: the
  position NEES then uses the x-y block (dof 2) and the rotation NEES the yaw variance
  (dof 1).
- **Singular covariances** (a zero variance in a used block) are skipped and counted.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from loceval.assessment.uncertainty import n_effective
from loceval.core.arrays import BoolArray, FloatArray
from loceval.core.rotation import Rotation
from loceval.errors import InputError, MetricError

__all__ = [
    "Consistency",
    "ConsistencyVerdict",
    "NEESResult",
    "check_consistency",
    "compute_nees",
    "covariance_in_aligned_frame",
    "is_planar",
    "nees_values",
    "rotation_errors_rotvec",
]

logger = logging.getLogger(__name__)

_TINY_VARIANCE = 1e-12
"""A variance at or below this (m² or rad²) is "not estimated" (AMCL's z)."""
_PLACEHOLDER_VARIANCE = 1e3
"""A variance at or above this is a placeholder for "unknown" (ROS drivers use 1e6, 9999)."""
_SINGULAR_RATIO = 1e-12
"""A block whose smallest eigenvalue is below this share of its largest is singular."""
_MIN_POSES = 8


class ConsistencyVerdict(StrEnum):
    """Whether a reported covariance matches the errors."""

    CONSISTENT = "consistent"
    CONSERVATIVE = "conservative"
    OVERCONFIDENT = "overconfident"


def covariance_in_aligned_frame(
    cov: FloatArray, *, rotation: FloatArray, scale: float = 1.0
) -> FloatArray:
    """Return position covariances mapped by an alignment ``x -> s R x + t``: ``s² R S Rᵀ``.

    For rotation-vector covariances about fixed axes use ``scale=1`` (rotations only turn).
    :meth:`loceval.trajectory.Trajectory.transformed` does the same for a whole ``cov6``.

    Args:
        cov: (N, 3, 3) covariances in the estimate's frame.
        rotation: (3, 3) rotation R of the alignment.
        scale: scale s of the alignment (1 for SE(3)).

    Raises:
        InputError: shapes other than (N, 3, 3) and (3, 3), or a scale that is not positive.
    """
    s = np.asarray(cov, dtype=np.float64)
    r = np.asarray(rotation, dtype=np.float64)
    if s.ndim != 3 or s.shape[1:] != (3, 3) or r.shape != (3, 3):
        msg = (
            f"Covariances must be (N, 3, 3) and the rotation (3, 3), got {s.shape!r} and "
            f"{r.shape!r}."
        )
        raise InputError(msg)
    if not (np.isfinite(scale) and scale > 0):
        msg = f"The alignment scale must be positive and finite, got {scale!r}."
        raise InputError(msg)
    out: FloatArray = scale**2 * (r @ s @ r.T)
    return out


def is_planar(cov: FloatArray, *, what: str = "position") -> bool:
    """Whether a (N, 3, 3) covariance stack comes from a planar system.

    Positions are planar when z is unestimated, rotations when roll and pitch are. An
    axis is unestimated when its variance is zero (≤ 1e-12), a placeholder (≥ 1e3), or
    constant while the estimated axes' variances vary from pose to pose (a filter that
    fills it with a fixed value). A constant covariance on every axis is 3-D.

    Args:
        cov: (N, 3, 3) position (m²) or rotation (rad²) covariances.
        what: "position" (z unestimated) or "rotation" (roll and pitch unestimated).
    """
    variances = np.diagonal(cov, axis1=1, axis2=2)
    dropped, kept = ([2], [0, 1]) if what == "position" else ([0, 1], [2])
    off = variances[:, dropped]
    on = variances[:, kept]
    if (off <= _TINY_VARIANCE).all() or (off >= _PLACEHOLDER_VARIANCE).all():
        return True
    off_constant = bool((np.ptp(off, axis=0) <= 1e-9 * np.maximum(off.max(axis=0), 1.0)).all())
    on_varies = bool((np.ptp(on, axis=0) > 1e-6 * max(float(on.max()), _TINY_VARIANCE)).any())
    return off_constant and on_varies


def nees_values(errors: FloatArray, cov: FloatArray) -> tuple[FloatArray, BoolArray]:
    """Return per-pose ``eᵀ S⁻¹ e`` and which poses had a usable (non-singular) ``S``.

    Args:
        errors: (N, d) errors.
        cov: (N, d, d) covariances of the errors.

    Returns:
        ((N,) NEES, NaN where skipped; (N,) bool, True where ``S`` was usable).

    Raises:
        InputError: shapes that do not fit together, or NaN/inf.
    """
    e = np.asarray(errors, dtype=np.float64)
    s = np.asarray(cov, dtype=np.float64)
    if e.ndim != 2 or s.shape != (*e.shape, e.shape[1]):
        msg = (
            f"NEES needs (N, d) errors and (N, d, d) covariances, got {e.shape!r} and {s.shape!r}."
        )
        raise InputError(msg)
    if not (np.isfinite(e).all() and np.isfinite(s).all()):
        msg = "NEES got NaN or inf among the errors or covariances; drop those poses first."
        raise InputError(msg)
    eig = np.linalg.eigvalsh(0.5 * (s + s.transpose(0, 2, 1)))
    usable = (eig[:, 0] > _SINGULAR_RATIO * eig[:, -1]) & (eig[:, -1] > 0.0)
    out = np.full(e.shape[0], np.nan)
    if usable.any():
        solved = np.linalg.solve(s[usable], e[usable][:, :, None])[:, :, 0]
        out[usable] = np.einsum("ij,ij->i", e[usable], solved)
    return out, usable


@dataclass(frozen=True, slots=True, eq=False)
class NEESResult:
    """NEES of one block (position or rotation) over a run.

    Attributes:
        values: (N,) per-pose NEES, NaN where the covariance was singular.
        mean: mean NEES over the usable poses (``dof`` when consistent).
        dof: degrees of freedom (3; 2 for planar positions; 1 for a planar yaw).
        band95: 95 % band of the mean over ``n_effective`` poses.
        band95_independent: the band if the poses were independent (N usable poses).
        share_in_band: share of usable poses with NEES inside ``chi2.ppf([0.025,
            0.975], dof)`` (0.95 when consistent).
        n: usable poses.
        n_effective: effective sample size of the NEES series.
        skipped: poses skipped for a singular covariance.
        planar: whether the planar block was used.
        verdict: consistent / conservative / overconfident.
    """

    values: FloatArray
    mean: float
    dof: int
    band95: tuple[float, float]
    band95_independent: tuple[float, float]
    share_in_band: float
    n: int
    n_effective: float
    skipped: int
    planar: bool
    verdict: ConsistencyVerdict

    def to_dict(self) -> dict[str, object]:
        """Return the JSON contract ``{"mean", "dof", "band95", "share_in_band"}``."""
        return {
            "mean": self.mean,
            "dof": self.dof,
            "band95": list(self.band95),
            "share_in_band": self.share_in_band,
        }


def _chi2_band(dof: float) -> FloatArray:
    """Return the (2,) 2.5 % and 97.5 % quantiles of a chi-square with ``dof`` degrees."""
    from scipy.stats import chi2  # noqa: PLC0415  (scipy.stats costs 0.7 s to import)

    out: FloatArray = np.asarray(chi2.ppf([0.025, 0.975], dof), dtype=np.float64)
    return out


def compute_nees(
    errors: FloatArray, cov: FloatArray, *, planar: bool | None = None, what: str = "position"
) -> NEESResult:
    """Return the NEES of 3-D errors (positions in m or rotation vectors in rad).

    Args:
        errors: (N, 3) aligned errors: estimate minus reference, in the aligned frame.
        cov: (N, 3, 3) the estimate's covariances in the aligned frame (see
            :func:`covariance_in_aligned_frame`).
        planar: use the x-y block (positions, dof 2) or the z variance alone (rotations:
            yaw, dof 1); detected with :func:`is_planar` when None.
        what: "position" or "rotation", for the block a planar system keeps and the
            messages.

    Raises:
        InputError: shapes that do not fit, NaN/inf, or ``what`` not position/rotation.
        MetricError: fewer than 8 poses with a usable covariance.
    """
    e = np.asarray(errors, dtype=np.float64)
    s = np.asarray(cov, dtype=np.float64)
    if e.ndim != 2 or e.shape[1] != 3 or s.shape != (e.shape[0], 3, 3):
        msg = (
            f"NEES needs (N, 3) errors and (N, 3, 3) covariances, got {e.shape!r} and {s.shape!r}."
        )
        raise InputError(msg)
    if what not in {"position", "rotation"}:
        msg = f"NEES is computed for 'position' or 'rotation', got {what!r}."
        raise InputError(msg)
    if planar is None:
        planar = is_planar(s, what=what)
    keep = slice(0, 3)
    if planar:
        keep = slice(0, 2) if what == "position" else slice(2, 3)
    values, usable = nees_values(e[:, keep], s[:, keep, keep])
    dof = keep.stop - keep.start
    n = int(usable.sum())
    if n < _MIN_POSES:
        msg = (
            f"Only {n} of {e.shape[0]} poses have a usable {what} covariance (at least "
            f"{_MIN_POSES} needed); check that the system publishes its covariance."
        )
        raise MetricError(msg)
    skipped = int(e.shape[0] - n)
    if skipped:
        logger.warning("%d poses with a singular %s covariance skipped in NEES", skipped, what)
    used = values[usable]
    mean = float(used.mean())
    n_eff = n_effective(used)
    band = _chi2_band(n_eff * dof) / n_eff
    band_ind = _chi2_band(float(n * dof)) / n
    pose_lo, pose_hi = _chi2_band(float(dof))
    share = float(np.count_nonzero((used >= pose_lo) & (used <= pose_hi))) / n
    if mean < band[0]:
        verdict = ConsistencyVerdict.CONSERVATIVE
    elif mean > band[1]:
        verdict = ConsistencyVerdict.OVERCONFIDENT
    else:
        verdict = ConsistencyVerdict.CONSISTENT
    values.flags.writeable = False
    return NEESResult(
        values=values,
        mean=mean,
        dof=dof,
        band95=(float(band[0]), float(band[1])),
        band95_independent=(float(band_ind[0]), float(band_ind[1])),
        share_in_band=share,
        n=n,
        n_effective=n_eff,
        skipped=skipped,
        planar=planar,
        verdict=verdict,
    )


def rotation_errors_rotvec(ref_quat_xyzw: FloatArray, est_quat_xyzw: FloatArray) -> FloatArray:
    """Return (N, 3) rotation-vector errors about the fixed (world) axes, in radians.

    ``δθ = Log(R_est R_refᵀ)``: the small rotation that carries the reference orientation
    to the estimate, expressed in the world frame, the convention of the rotation block of
    a ROS ``PoseWithCovariance`` ("rotation about the fixed X, Y, Z axes").

    Args:
        ref_quat_xyzw: (N, 4) reference orientations (aligned frame).
        est_quat_xyzw: (N, 4) estimate orientations (aligned frame).
    """
    rel = Rotation.from_quat(est_quat_xyzw) * Rotation.from_quat(ref_quat_xyzw).inv()
    out: FloatArray = rel.as_rotvec()
    return out


@dataclass(frozen=True, slots=True)
class Consistency:
    """NEES of positions (and rotations where both sides have them) and the verdict.

    Attributes:
        nees_position: position NEES.
        nees_rotation: rotation NEES, or None without orientations or rotation covariance.
        verdict: overconfident if either block is (the unsafe failure), else conservative
            if either block is, else consistent.
        warnings: sentences about planar detection and skipped poses.
    """

    nees_position: NEESResult
    nees_rotation: NEESResult | None
    verdict: ConsistencyVerdict
    warnings: tuple[str, ...]

    def to_dict(self) -> dict[str, object]:
        """Return the JSON contract ``{"nees_position", "nees_rotation", "verdict"}``."""
        return {
            "nees_position": self.nees_position.to_dict(),
            "nees_rotation": None if self.nees_rotation is None else self.nees_rotation.to_dict(),
            "verdict": self.verdict.value,
        }


def _notes(result: NEESResult, what: str) -> list[str]:
    """Return the sentences a NEES result warrants."""
    notes = []
    if result.planar:
        axes, block = ("z", "x-y block (dof 2)")
        if what == "rotation":
            axes, block = ("roll and pitch", "yaw variance (dof 1)")
        notes.append(
            f"The {what} covariance leaves {axes} unestimated (zero, placeholder or constant "
            f"variance), so the {what} NEES uses the {block}."
        )
    if result.skipped:
        notes.append(
            f"{result.skipped} poses with a singular {what} covariance were skipped in the NEES."
        )
    return notes


def check_consistency(
    position_errors_xyz: FloatArray,
    position_cov: FloatArray,
    *,
    rotation_errors: FloatArray | None = None,
    rotation_cov: FloatArray | None = None,
    planar: bool | None = None,
) -> Consistency:
    """Return position and rotation NEES and whether the reported covariance is honest.

    Args:
        position_errors_xyz: (N, 3) aligned position errors (estimate minus reference), m.
        position_cov: (N, 3, 3) the estimate's position covariances in the aligned frame
            (m², times the scale squared under Sim(3): :func:`covariance_in_aligned_frame`).
        rotation_errors: (N, 3) rotation-vector errors about the world axes, rad
            (:func:`rotation_errors_rotvec`), or None.
        rotation_cov: (N, 3, 3) the estimate's rotation covariances in the aligned frame,
            rad², or None.
        planar: force the planar (True) or 3-D (False) blocks; detected per block when None.

    Raises:
        InputError: shapes that do not fit, NaN/inf, or only one of the rotation inputs.
        MetricError: fewer than 8 poses with a usable covariance.
    """
    position = compute_nees(position_errors_xyz, position_cov, planar=planar, what="position")
    if (rotation_errors is None) != (rotation_cov is None):
        msg = "Rotation NEES needs both the rotation errors and the rotation covariances."
        raise InputError(msg)
    rotation = None
    if rotation_errors is not None and rotation_cov is not None:
        rotation = compute_nees(rotation_errors, rotation_cov, planar=planar, what="rotation")
    verdicts = {position.verdict} | ({rotation.verdict} if rotation else set())
    if ConsistencyVerdict.OVERCONFIDENT in verdicts:
        verdict = ConsistencyVerdict.OVERCONFIDENT
    elif ConsistencyVerdict.CONSERVATIVE in verdicts:
        verdict = ConsistencyVerdict.CONSERVATIVE
    else:
        verdict = ConsistencyVerdict.CONSISTENT
    notes = _notes(position, "position") + (_notes(rotation, "rotation") if rotation else [])
    return Consistency(
        nees_position=position, nees_rotation=rotation, verdict=verdict, warnings=tuple(notes)
    )
