"""How far an evaluation's figures can be trusted: intervals, comparisons, NEES, reference error.

The evaluation (:mod:`loceval.evaluation`) measures; this module adds what issue 18 asks of
every headline figure, from the cores :mod:`loceval.assessment.uncertainty`,
:mod:`loceval.assessment.comparison`, :mod:`loceval.assessment.consistency` and
:mod:`loceval.assessment.reference_error`:

- 95 % block-bootstrap intervals and effective sample sizes of the ATE and RPE statistics
  (translation and rotation) and of the shares within the thresholds (skipped when the
  confidence intervals are turned off);
- the tolerance verdict's interval of the share within (PASS, FAIL or undecided);
- the NEES consistency of the estimate's own covariance, when it reports one;
- the RMSE with the reference's own error taken out, and whether the reference is accurate
  enough for the system;
- the paired comparisons of every two estimates' ATE and RPE RMSE.

It imports scipy (through the cores), so :mod:`loceval.evaluation` imports it only when an
evaluation needs it: an evaluation without intervals, covariances or a reference error
loads no scipy. The comparison, consistency and reference-error cores are imported in the
functions that use them, so an evaluation that only needs intervals loads none of them.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

from loceval.assessment.uncertainty import (
    DEFAULT_RESAMPLES,
    DEFAULT_SEED,
    IntervalStats,
    ToleranceVerdict,
    interval_stats,
    tolerance_verdict,
)
from loceval.errors import InputError, MetricError

if TYPE_CHECKING:  # the cores below load when an evaluation needs them
    from loceval.assessment.comparison import Comparison
    from loceval.assessment.consistency import Consistency
    from loceval.assessment.reference_error import ReferenceErrorCheck
    from loceval.core.arrays import FloatArray
    from loceval.metrics.pose_errors import ErrorSeries
    from loceval.trajectory import Trajectory

__all__ = [
    "SERIES",
    "Assessment",
    "assess",
    "compare_estimates",
]

SERIES = ("ate_translation", "ate_rotation", "rpe_translation", "rpe_rotation")
"""The error series that get intervals, as :func:`assess` names them."""

_PARALLEL_FROM = 200_000
"""Series at least this long get their intervals in threads (NumPy and SciPy's FFT release
the GIL; each series has its own seeded generator, so the result does not change). Shorter
ones are computed on one thread: threads save wall time but cost CPU time (measured on the
four series of 50,000 errors of the 200,000 / 50,000-pose benchmark on two vCPUs: 0.12 s of
CPU in threads, 0.09 s on one), and below 200,000 errors the wall time saved is a few
hundredths of a second."""

_SERIES_WORDS = {
    "ate_translation": "ATE translation",
    "ate_rotation": "ATE rotation",
    "rpe_translation": "RPE translation",
    "rpe_rotation": "RPE rotation",
}


@dataclass(frozen=True, slots=True, eq=False)
class Assessment:
    """What an estimate's figures are worth.

    Attributes:
        intervals: series name (see :data:`SERIES`) -> 95 % intervals; a series is absent
            when intervals are off, the series does not exist, or it has too few errors.
        tolerance: the tolerance verdict with the share's interval, if a tolerance was
            given and intervals are on.
        consistency: the NEES of the estimate's reported covariance, or None.
        reference_error: ``"ate"`` and ``"rpe"`` -> the RMSE corrected for the reference's
            own error; empty when the reference's error is not known.
        warnings: sentences for the user (too few errors, inadequate reference, NEES notes).
    """

    intervals: Mapping[str, IntervalStats]
    tolerance: ToleranceVerdict | None
    consistency: Consistency | None
    reference_error: Mapping[str, ReferenceErrorCheck]
    warnings: tuple[str, ...]

    def consistency_dict(self) -> dict[str, object] | None:
        """Return the result document's consistency (NEES) block, or None."""
        return None if self.consistency is None else self.consistency.to_dict()

    def reference_error_dict(self) -> dict[str, object] | None:
        """Return the result document's reference-error block, or None without checks."""
        return {k: c.to_dict() for k, c in self.reference_error.items()} or None


def assess(
    *,
    reference: Trajectory,
    aligned: Trajectory,
    series: Mapping[str, ErrorSeries | None],
    thresholds_m: Sequence[float],
    tolerance: tuple[float, float] | None,
    confidence: bool,
    reference_sigma_m: float | None,
    full_reference: Trajectory | None = None,
) -> Assessment:
    """Return the intervals, tolerance outcome, consistency and reference-error check.

    Args:
        reference: the reference at the matched stamps.
        aligned: the matched estimate after alignment (its ``cov6`` in the aligned frame).
        series: the error series by name (:data:`SERIES`), None where not computed.
        thresholds_m: distances of the share-within intervals (of the ATE translation).
        tolerance: ``(distance_m, required_share)`` of the verdict, if any.
        confidence: compute the bootstrap intervals (False: skip them).
        reference_sigma_m: the reference's per-axis standard deviation, metres, if known.
        full_reference: the whole reference, whose ``cov6`` (if any) gives the reference's
            error when ``reference_sigma_m`` is None.

    Returns:
        The assessment.
    """
    notes: list[str] = []
    intervals: dict[str, IntervalStats] = {}
    verdict = None
    if confidence:
        wanted = list(thresholds_m)
        if tolerance is not None and tolerance[0] not in wanted:
            wanted.append(tolerance[0])
        intervals = _intervals(series, wanted, notes)
        ate = series.get("ate_translation")
        if tolerance is not None and ate is not None and "ate_translation" in intervals:
            verdict = tolerance_verdict(
                ate.values,
                distance_m=tolerance[0],
                required_share=tolerance[1],
                intervals=intervals["ate_translation"],
            )
    consistency = _consistency(reference, aligned, notes)
    checks = _reference_checks(
        series,
        reference_sigma_m=reference_sigma_m,
        full_reference=full_reference,
        tolerance_m=None if tolerance is None else tolerance[0],
        notes=notes,
    )
    return Assessment(
        intervals=intervals,
        tolerance=verdict,
        consistency=consistency,
        reference_error=checks,
        warnings=tuple(notes),
    )


def _intervals(
    series: Mapping[str, ErrorSeries | None], thresholds_m: Sequence[float], notes: list[str]
) -> dict[str, IntervalStats]:
    """Return the intervals of every series with at least 8 errors (threads for long ones)."""
    todo = {name: s for name in SERIES if (s := series.get(name)) is not None and len(s) >= 8}
    for name in SERIES:
        errors = series.get(name)
        if errors is not None and name not in todo:
            notes.append(
                f"The {_SERIES_WORDS[name]} has {len(errors)} errors, too few for a "
                "confidence interval (at least 8 needed)."
            )

    def one(name: str) -> IntervalStats:
        return interval_stats(
            todo[name].values,
            resamples=DEFAULT_RESAMPLES,
            seed=DEFAULT_SEED,
            thresholds_m=thresholds_m if name == "ate_translation" else (),
        )

    workers = min(len(todo), os.cpu_count() or 1)
    if workers > 1 and max(len(s) for s in todo.values()) >= _PARALLEL_FROM:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            return dict(zip(todo, pool.map(one, todo), strict=True))
    return {name: one(name) for name in todo}


def _consistency(
    reference: Trajectory, aligned: Trajectory, notes: list[str]
) -> Consistency | None:
    """Return the NEES of the aligned estimate's covariance, or None without one."""
    cov = aligned.cov6
    if cov is None:
        return None
    from loceval.assessment.consistency import check_consistency, rotation_errors_rotvec  # noqa: PLC0415

    errors = aligned.positions_xyz - reference.positions_xyz
    rotation: tuple[FloatArray, FloatArray] | None = None
    if aligned.quat_xyzw is not None and reference.quat_xyzw is not None:
        rotation = (rotation_errors_rotvec(reference.quat_xyzw, aligned.quat_xyzw), cov[:, 3:, 3:])
    try:
        try:
            result = check_consistency(
                errors,
                cov[:, :3, :3],
                rotation_errors=None if rotation is None else rotation[0],
                rotation_cov=None if rotation is None else rotation[1],
            )
        except MetricError:
            if rotation is None:
                raise
            result = check_consistency(errors, cov[:, :3, :3])  # no usable rotation block
    except MetricError as err:
        notes.append(f"The reported covariance is not checked: {err}")
        return None
    notes.extend(result.warnings)
    return result


def _reference_checks(
    series: Mapping[str, ErrorSeries | None],
    *,
    reference_sigma_m: float | None,
    full_reference: Trajectory | None,
    tolerance_m: float | None,
    notes: list[str],
) -> dict[str, ReferenceErrorCheck]:
    """Return the ATE and RPE RMSE corrected for the reference's own error."""
    reference_cov = None
    if reference_sigma_m is None:
        if full_reference is None or full_reference.cov6 is None:
            return {}
        reference_cov = full_reference.cov6[:, :3, :3]
    from loceval.assessment.reference_error import check_reference_error  # noqa: PLC0415

    checks: dict[str, ReferenceErrorCheck] = {}
    for key, name, poses in (("ate", "ate_translation", 1), ("rpe", "rpe_translation", 2)):
        errors = series.get(name)
        if errors is None or len(errors) == 0 or errors.unit != "m":
            continue
        check = check_reference_error(
            errors.stats.rmse,
            reference_sigma_m=reference_sigma_m,
            reference_cov=reference_cov,
            poses_per_error=poses,
            tolerance_m=tolerance_m if key == "ate" else None,
        )
        checks[key] = check
        if check.summary:
            notes.append(f"{key.upper()}: {check.summary}")
    return checks


def compare_estimates(
    named: Sequence[tuple[str, ErrorSeries, ErrorSeries]],
) -> tuple[list[Comparison], list[str]]:
    """Compare every two estimates' ATE and RPE translation RMSE, in the order given.

    Args:
        named: ``(name, ATE translation, RPE translation)`` of each estimate, all against
            the same reference.

    Returns:
        The comparisons (pairs (0, 1), (0, 2), ..., (1, 2), ...; ATE then RPE per pair) and
        sentences about pairs that could not be compared (too few common stamps).
    """
    out: list[Comparison] = []
    notes: list[str] = []
    if len(named) < 2:
        return out, notes
    from loceval.assessment.comparison import ComparedMetric, compare_error_series  # noqa: PLC0415

    for i, (name_a, ate_a, rpe_a) in enumerate(named):
        for name_b, ate_b, rpe_b in named[i + 1 :]:
            for metric, sa, sb in (
                (ComparedMetric.ATE_RMSE, ate_a, ate_b),
                (ComparedMetric.RPE_RMSE, rpe_a, rpe_b),
            ):
                if sa.unit != sb.unit:
                    continue
                try:
                    out.append(compare_error_series(sa, sb, a=name_a, b=name_b, metric=metric))
                except (InputError, MetricError) as err:
                    notes.append(f"{metric.label} of {name_a} and {name_b} not compared: {err}")
    return out, notes
