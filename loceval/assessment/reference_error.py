"""The ground truth's own error: take it out of the RMSE and say when it is too large.

A measured error is the system's error plus the reference's. With the two independent
and the reference's error zero-mean, ``E|e_measured|² = E|e_system|² + E|n_ref|²`` (the
cross term vanishes), so ``RMSE_system² = RMSE_measured² - E|n_ref|²`` (clipped at 0).
``E|n_ref|²`` is ``dof · σ²`` for a per-axis standard deviation σ (OptiTrack's ±0.20 mm:
``σ = 0.0002``) or the mean trace of the reference's per-pose position covariances; an RPE
error involves two reference poses, so it carries the reference's error twice.

Only the RMSE is corrected: the mean, median and shares of error norms have no such
closed form, and at the sizes where the correction matters the ground truth is not
accurate enough anyway. That is the second thing checked here: a reference whose own RMS
error exceeds a third of the system's RMSE (or of the tolerance the system is judged
against) cannot tell the system's error from its own (e.g. a reference robot with 6.7 cm
error evaluating a 5 cm system).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from loceval.assessment.uncertainty import format_length_m
from loceval.core.arrays import FloatArray
from loceval.errors import InputError

__all__ = [
    "ADEQUACY_RATIO",
    "ReferenceErrorCheck",
    "check_reference_error",
    "reference_mean_square_m2",
]

ADEQUACY_RATIO = 1.0 / 3.0
"""Largest reference RMS error, as a share of the system's RMSE or the tolerance."""


def reference_mean_square_m2(
    *,
    reference_sigma_m: float | None = None,
    reference_cov: FloatArray | None = None,
    dof: int = 3,
) -> float:
    """Return ``E|n_ref|²``, the reference's mean squared position error, in m².

    Args:
        reference_sigma_m: the reference's per-axis standard deviation in metres.
        reference_cov: (N, 3, 3) the reference's per-pose position covariances, m²; the
            mean trace of their first ``dof`` axes is used.
        dof: axes the error is measured on (3; 2 for planar errors).

    Raises:
        InputError: neither or both given, a negative or non-finite sigma, a dof other
            than 1-3, or covariances of another shape.
    """
    if (reference_sigma_m is None) == (reference_cov is None):
        msg = "Give the reference's error either as one standard deviation or as covariances."
        raise InputError(msg, option="reference_sigma_m")
    if dof not in {1, 2, 3}:
        msg = f"The reference error's degrees of freedom must be 1, 2 or 3, got {dof!r}."
        raise InputError(msg)
    if reference_sigma_m is not None:
        if not (math.isfinite(reference_sigma_m) and reference_sigma_m >= 0.0):
            msg = (
                f"The reference's standard deviation must be a non-negative number of metres, "
                f"got {reference_sigma_m!r}."
            )
            raise InputError(msg, option="reference_sigma_m")
        return dof * reference_sigma_m**2
    cov = np.asarray(reference_cov, dtype=np.float64)
    if cov.ndim != 3 or cov.shape[1:] != (3, 3) or cov.shape[0] == 0:
        msg = f"Reference covariances must have shape (N, 3, 3), got {cov.shape!r}."
        raise InputError(msg)
    if not np.isfinite(cov).all():
        msg = "Reference covariances contain NaN or inf; drop those poses first."
        raise InputError(msg)
    return float(np.trace(cov[:, :dof, :dof], axis1=1, axis2=2).mean())


@dataclass(frozen=True, slots=True)
class ReferenceErrorCheck:
    """The RMSE with the reference's contribution removed, and whether the reference suffices.

    Attributes:
        rmse_m: the measured RMSE.
        corrected_rmse_m: ``sqrt(max(rmse² - reference_ms, 0))``: the system's own RMSE.
        reference_rms_m: the reference's RMS error in this metric, ``sqrt(reference_ms)``.
        limit_m: what the reference is held against: the smaller of the corrected RMSE and
            the tolerance distance.
        adequate: whether ``reference_rms_m ≤ limit_m / 3``.
        summary: a sentence when the reference is not adequate, else "".
    """

    rmse_m: float
    corrected_rmse_m: float
    reference_rms_m: float
    limit_m: float
    adequate: bool
    summary: str

    def to_dict(self) -> dict[str, object]:
        """Return the JSON form."""
        return {
            "rmse": self.rmse_m,
            "corrected_rmse": self.corrected_rmse_m,
            "reference_rms": self.reference_rms_m,
            "adequate": self.adequate,
            "summary": self.summary,
        }


def check_reference_error(
    rmse_m: float,
    *,
    reference_sigma_m: float | None = None,
    reference_cov: FloatArray | None = None,
    dof: int = 3,
    poses_per_error: int = 1,
    tolerance_m: float | None = None,
) -> ReferenceErrorCheck:
    """Return the RMSE corrected for the reference's own error and the adequacy check.

    Args:
        rmse_m: the measured RMSE (ATE translation, or RPE translation in metres).
        reference_sigma_m: the reference's per-axis standard deviation in metres.
        reference_cov: (N, 3, 3) the reference's per-pose position covariances, m².
        dof: axes the error is measured on (3; 2 for planar errors).
        poses_per_error: reference poses in one error: 1 for ATE, 2 for RPE.
        tolerance_m: the tolerance distance the system is judged against, if any.

    Raises:
        InputError: a negative RMSE or tolerance, poses per error other than 1 or 2, or
            see :func:`reference_mean_square_m2`.
    """
    if not (math.isfinite(rmse_m) and rmse_m >= 0.0):
        msg = f"The RMSE must be a non-negative number of metres, got {rmse_m!r}."
        raise InputError(msg)
    if poses_per_error not in {1, 2}:
        msg = f"An error involves 1 (ATE) or 2 (RPE) reference poses, got {poses_per_error!r}."
        raise InputError(msg)
    if tolerance_m is not None and not (math.isfinite(tolerance_m) and tolerance_m > 0.0):
        msg = f"The tolerance distance must be positive metres, got {tolerance_m!r}."
        raise InputError(msg, option="tolerance")
    ref_ms = poses_per_error * reference_mean_square_m2(
        reference_sigma_m=reference_sigma_m, reference_cov=reference_cov, dof=dof
    )
    corrected = math.sqrt(max(rmse_m**2 - ref_ms, 0.0))
    ref_rms = math.sqrt(ref_ms)
    limit = corrected if tolerance_m is None else min(corrected, tolerance_m)
    against = "the system's own RMSE" if limit == corrected else "the tolerance"
    adequate = ref_rms <= ADEQUACY_RATIO * limit
    summary = ""
    if not adequate:
        summary = (
            f"The ground truth's own error ({format_length_m(ref_rms)} RMS) is more than a "
            f"third of {against} ({format_length_m(limit)}), so it cannot tell the "
            "system's error from its own: evaluate against a more accurate reference."
        )
    return ReferenceErrorCheck(
        rmse_m=float(rmse_m),
        corrected_rmse_m=corrected,
        reference_rms_m=ref_rms,
        limit_m=limit,
        adequate=adequate,
        summary=summary,
    )
