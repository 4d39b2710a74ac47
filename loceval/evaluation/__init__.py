"""The one evaluation pipeline: associate, align, measure; used by the CLI, service and jobs."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from typing import TYPE_CHECKING

import numpy as np

from loceval._version import __version__
from loceval.assessment.verdict import FailingSpan, Tolerance, Verdict, tolerance_verdict_of
from loceval.calibration.offsets import OffsetCheck, check_offsets, parse_offset
from loceval.core.arrays import IntArray
from loceval.core.gaps import gap_threshold_ns, path_breaks
from loceval.core.quantities import ARROW, format_duration
from loceval.errors import InputError, LocevalError
from loceval.evaluation.config import EvaluationConfig
from loceval.metrics.excursions import Excursion, find_excursions
from loceval.metrics.pose_errors import (
    ErrorSeries,
    WorstPose,
    compute_ate,
    compute_drift,
    compute_rpe,
    greatest_errors,
    rpe_pairs,
    share_within,
)
from loceval.registration.alignment import Alignment, AlignMethod, align
from loceval.registration.association import Association, associate, association_notes
from loceval.trajectory import Trajectory

if TYPE_CHECKING:  # the trials' and the building's modules load when an evaluation has them
    from loceval.assessment.assess import Assessment
    from loceval.assessment.baseline import BaselineComparison
    from loceval.assessment.comparison import Comparison
    from loceval.assessment.spaces import Building
    from loceval.assessment.trial_comparison import SystemComparison
    from loceval.assessment.trials import FailedTrial, SystemTrials
    from loceval.assessment.uncertainty import IntervalStats
    from loceval.maps import MapEvaluation
    from loceval.radio.ranging import RangingResult

__all__ = [
    "EstimateResult",
    "EvaluationConfig",
    "EvaluationResult",
    "FailingSpan",
    "Tolerance",
    "Verdict",
    "evaluate",
    "parse_offset",
]

_NS_PER_S = 1_000_000_000

ProgressCallback = Callable[[str, float], None]
"""Called with a stage name and the fraction of the evaluation done (0..1)."""


@dataclass(frozen=True, slots=True, eq=False)
class EstimateResult:
    """Everything measured for one estimate.

    Attributes:
        estimate: the estimate as read.
        association: the matched pairs (reference interpolated at the estimate's stamps).
        alignment: the transform found.
        aligned: the matched estimate poses after alignment (same stamps as
            ``association.reference``).
        ate_translation: ATE per matched pose, metres.
        ate_rotation: ATE rotation per matched pose, degrees (None: position-only).
        rpe_translation: RPE per pair, metres.
        rpe_rotation: RPE rotation per pair, degrees (None: position-only).
        rpe_index: (K, 2) matched-pose indices of each RPE pair.
        drift: drift per segment, percent (None: path too short).
        within: share of ATE translation errors ≤ each threshold.
        worst: the greatest ATE translation errors, largest first.
        verdict: pass/fail against the tolerance, if one was given.
        warnings: what the user should know (dropped poses, gaps, reader notes).
        assessment: intervals, consistency and reference error (None: nothing to assess).
        offsets: the time and device offsets given, estimated and applied.
        excursions: the stretches outside the tracked room (:mod:`loceval.metrics.excursions`).
        notes: what the evaluation found that asks nothing of the user (the clock check).
        system: the system this estimate is a trial of (None: not a trial).
        coverage: the share of the reference's duration it tracked (matched poses no
            farther apart than a gap), 0..1.
    """

    estimate: Trajectory
    association: Association
    alignment: Alignment
    aligned: Trajectory
    ate_translation: ErrorSeries
    ate_rotation: ErrorSeries | None
    rpe_translation: ErrorSeries
    rpe_rotation: ErrorSeries | None
    rpe_index: IntArray
    drift: ErrorSeries | None
    within: Mapping[float, float]
    worst: tuple[WorstPose, ...]
    verdict: Verdict | None
    warnings: tuple[str, ...]
    assessment: Assessment | None = None
    offsets: OffsetCheck | None = None
    excursions: tuple[Excursion, ...] = ()
    notes: tuple[str, ...] = ()
    system: str | None = None
    coverage: float | None = None

    @property
    def name(self) -> str:
        """Return the estimate's name."""
        return self.estimate.name

    @property
    def reference(self) -> Trajectory:
        """Return the reference at the matched stamps."""
        return self.association.reference


@dataclass(frozen=True, slots=True, eq=False)
class EvaluationResult:
    """A whole evaluation: one reference, one or more estimates, and how it was made.

    ``ranging`` holds the ranging evaluation when the estimates were positioned from radio
    ranges (:mod:`loceval.radio_evaluation`); its figures, with ``ranging_options``, are the
    document's ``ranging`` object.
    """

    reference: Trajectory
    estimates: tuple[EstimateResult, ...]
    config: EvaluationConfig
    reference_warnings: tuple[str, ...]
    created_at: str
    loceval_version: str = __version__
    inputs: tuple[Mapping[str, object], ...] = ()
    comparisons: tuple[Comparison, ...] | None = None
    """Every two estimates' ATE and RPE RMSE compared; None when intervals are off."""
    comparison_notes: tuple[str, ...] = ()
    """Why two estimates were not compared (too few shared stamps): about the pair."""
    ranging: RangingResult | None = None
    ranging_options: Mapping[str, object] = field(default_factory=dict)
    map: MapEvaluation | None = None
    """The robot's map against the building plan (:mod:`loceval.maps`), if one was given."""
    building: Building | None = None
    """The building model the paths were placed on: its spaces and warnings
    (:func:`loceval.assessment.spaces.on_building`), once an exporter placed them."""
    systems: tuple[SystemTrials, ...] = ()
    """The systems whose trials the estimates are (:mod:`loceval.assessment.trials`)."""
    system_comparisons: tuple[SystemComparison, ...] = ()
    """Every two systems compared over all their trials."""
    baseline: BaselineComparison | None = None
    """Each estimate and system against an earlier result (:mod:`loceval.assessment.baseline`)."""

    @property
    def failed_trials(self) -> tuple[FailedTrial, ...]:
        """Return every failed trial, system by system."""
        return tuple(f for s in self.systems for f in s.failed)

    def with_building(self, building: Building) -> EvaluationResult:
        """Return the result placed on ``building``: each stretch in its space, kept.

        See :func:`loceval.assessment.spaces.locate_verdict`.
        """
        from loceval.assessment.spaces import locate_verdict  # noqa: PLC0415

        estimates = tuple(
            replace(e, verdict=locate_verdict(e.verdict, e.reference.positions_xyz, building))
            if e.verdict is not None
            else e
            for e in self.estimates
        )
        return replace(self, estimates=estimates, building=building)

    def to_dict(self) -> dict[str, object]:
        """Return the CLI's ``--json`` document (also the service's result schema)."""
        ref = self.reference
        t0 = int(ref.stamps_ns[0])
        ranging = (
            {} if self.ranging is None else {"ranging": self.ranging.document(self.ranging_options)}
        )
        return {
            "loceval_version": self.loceval_version,
            "created_at": self.created_at,
            "options": self.config.to_dict(),
            "inputs": [dict(i) for i in self.inputs],
            "reference": {
                "name": ref.name,
                "source": ref.source,
                "poses": len(ref),
                "duration_s": ref.duration_s,
                "length_m": ref.length_m,
                "rate_hz": ref.rate_hz,
                "frame_id": ref.frame_id,
                "gaps": [
                    {
                        "start_s": (a - int(ref.stamps_ns[0])) / _NS_PER_S,
                        "duration_s": (b - a) / _NS_PER_S,
                    }
                    for a, b in ref.tracking_losses(round(self.config.max_gap_s * _NS_PER_S))
                ],
                "warnings": list(self.reference_warnings),
                "notes": list(ref.notes),
            },
            **ranging,
            **({} if self.map is None else {"map": self.map.to_dict()}),
            **({} if self.building is None else {"building": self.building.to_dict()}),
            "estimates": [_estimate_dict(e, self.config, t0) for e in self.estimates],
            "comparisons": None
            if self.comparisons is None
            else [c.to_dict() for c in self.comparisons],
            "comparison_notes": list(self.comparison_notes),
            "systems": [s.to_dict() for s in self.systems],
            "system_comparisons": [c.to_dict() for c in self.system_comparisons],
            "baseline": None if self.baseline is None else self.baseline.to_dict(),
        }


def evaluate(
    reference: Trajectory,
    estimates: Sequence[Trajectory],
    config: EvaluationConfig | None = None,
    *,
    inputs: Sequence[Mapping[str, object]] = (),
    progress: ProgressCallback | None = None,
    systems: Sequence[str | None] | None = None,
    failed_trials: Sequence[FailedTrial] = (),
) -> EvaluationResult:
    """Evaluate one or more estimates against a reference.

    Estimates that name a system are its trials (:mod:`loceval.assessment.trials`): a trial
    whose evaluation raises a :class:`~loceval.errors.LocevalError`, or that tracks less than
    ``config.min_trial_coverage`` of the reference's duration, is a failed trial, counted
    under its system; the others go on. An estimate of no system raises as before.

    Args:
        reference: the ground truth.
        estimates: the systems under evaluation (names should differ).
        config: the options; defaults as on the CLI.
        inputs: provenance of the input files (path, sha256, bytes) for the result.
        progress: called with (stage, fraction done).
        systems: the system of each estimate (None: not a trial), as long as ``estimates``.
        failed_trials: trials that failed before the evaluation (an unreadable file).

    Returns:
        The evaluation result.

    Raises:
        InputError: no estimate given.
        AssociationError: an estimate does not overlap the reference in time.
        AlignmentError: the alignment is undetermined.
        MetricError: a metric cannot be computed (RPE delta too long).
    """
    config = config or EvaluationConfig()
    systems = list(systems) if systems is not None else [None] * len(estimates)
    if len(systems) != len(estimates):
        msg = f"Give a system per estimate: {len(estimates)} estimates, {len(systems)} systems."
        raise InputError(msg)
    if not estimates and not failed_trials:
        msg = "Give at least one estimate to evaluate against the reference."
        raise InputError(msg)
    report = progress or (lambda _stage, _fraction: None)
    ref_notes = list(reference.warnings)
    recorded = reference
    if config.reference_offset is not None:
        reference = reference.with_body_offset(config.reference_offset)
        ref_notes.append(f"Device offset applied to the reference (rigid body {ARROW} sensor).")
    min_gap_ns = round(config.max_gap_s * _NS_PER_S)
    gaps = reference.tracking_losses(min_gap_ns)
    if gaps:
        longest = max(b - a for a, b in gaps) / _NS_PER_S
        ref_gap_s = gap_threshold_ns(reference.stamps_ns, min_gap_ns=min_gap_ns) / _NS_PER_S
        ref_notes.append(
            f"The reference has {len(gaps)} {'gap' if len(gaps) == 1 else 'gaps'} longer than "
            f"{format_duration(ref_gap_s)} ({reference.loss_words}; longest "
            f"{format_duration(longest)}); estimate poses in them are not evaluated."
        )
    results = []
    failed = list(failed_trials)
    for k, (estimate, system) in enumerate(zip(estimates, systems, strict=True)):
        report(f"evaluating {estimate.name or k}", k / len(estimates))
        if system is None:
            results.append(_evaluate_one(reference, estimate, config, recorded=recorded))
            continue
        trial = _evaluate_trial(
            reference,
            estimate,
            config,
            recorded=recorded,
            system=system,
            label=estimate.name or f"estimate {k + 1}",
        )
        if isinstance(trial, EstimateResult):
            results.append(trial)
        else:  # a trial that fails is counted under its system; the others go on
            failed.append(trial)
    if not results:
        reasons = "; ".join(f"{f.name}: {f.reason}" for f in failed)
        msg = f"Every trial failed, so there is nothing to evaluate ({reasons})."
        raise InputError(msg)
    trial_systems, system_comparisons = _systems(results, failed, config)
    comparisons = None
    comparison_notes: tuple[str, ...] = ()
    if not config.no_ci:
        from loceval.assessment.assess import compare_estimates  # noqa: PLC0415  (scipy)

        # trials are compared system against system over all their trials, not pairwise
        found, notes = compare_estimates(
            [
                (e.name or f"estimate {k + 1}", e.ate_translation, e.rpe_translation)
                for k, e in enumerate(results)
                if e.system is None
            ]
        )
        comparisons, comparison_notes = tuple(found), tuple(notes)
    report("done", 1.0)
    return EvaluationResult(
        reference=reference,
        estimates=tuple(results),
        config=config,
        reference_warnings=tuple(ref_notes),
        created_at=datetime.now(UTC).isoformat(timespec="seconds"),
        inputs=tuple(inputs),
        comparisons=comparisons,
        comparison_notes=comparison_notes,
        systems=trial_systems,
        system_comparisons=system_comparisons,
    )


def _evaluate_trial(
    reference: Trajectory,
    estimate: Trajectory,
    config: EvaluationConfig,
    *,
    recorded: Trajectory,
    system: str,
    label: str,
) -> EstimateResult | FailedTrial:
    """Evaluate a trial of ``system``, or return it failed (a LocevalError) under ``label``."""
    from loceval.assessment.trials import FailedTrial, tracked_share  # noqa: PLC0415

    try:
        one = _evaluate_one(reference, estimate, config, recorded=recorded)
    except LocevalError as err:
        return FailedTrial(label, system, err.code, str(err))
    min_gap_ns = round(config.max_gap_s * _NS_PER_S)
    tracked = tracked_share(
        reference.stamps_ns, one.association.reference.stamps_ns, min_gap_ns=min_gap_ns
    )
    return replace(one, system=system, coverage=tracked)


def _systems(
    results: Sequence[EstimateResult], failed: list[FailedTrial], config: EvaluationConfig
) -> tuple[tuple[SystemTrials, ...], tuple[SystemComparison, ...]]:
    """Group the trials by system and compare every two systems; none without trials.

    The trials' modules load only for an evaluation that has trials.
    """
    trials = [e for e in results if e.system is not None]
    if not trials and not failed:
        return (), ()
    from loceval.assessment.trial_comparison import compare_all_systems  # noqa: PLC0415
    from loceval.assessment.trials import group_evaluated_trials, trial_figures  # noqa: PLC0415

    systems = group_evaluated_trials(
        [
            (trial_figures(e.name, e.system, _series_of(e)), e.coverage or 0.0)
            for e in trials
            if e.system is not None  # (for the type checker: every trial has one)
        ],
        failed,
        min_coverage=config.min_trial_coverage,
    )
    return systems, compare_all_systems(systems)


def _series_of(e: EstimateResult) -> dict[str, ErrorSeries | None]:
    """The error series of each trial metric (:data:`~loceval.assessment.trials.TRIAL_METRICS`)."""
    return {
        "ate_rmse": e.ate_translation,
        "rpe_rmse": e.rpe_translation,
        "ate_rot_rmse": e.ate_rotation,
        "rpe_rot_rmse": e.rpe_rotation,
    }


def _evaluate_one(
    reference: Trajectory, estimate: Trajectory, config: EvaluationConfig, *, recorded: Trajectory
) -> EstimateResult:
    notes = list(estimate.warnings)
    offsets = check_offsets(
        recorded,
        estimate,
        time_offset_s=None if config.auto_time_offset else config.time_offset_s,
        device=config.reference_offset,
        device_source=config.reference_offset_source,
        auto_device=config.auto_device,
        max_gap_s=config.max_gap_s,
        with_scale=config.align is AlignMethod.SIM3,
        clock_drift_ppm=None if config.auto_clock_drift else config.clock_drift_ppm,
        tolerance_s=config.max_dt_s,
    )
    notes.extend(offsets.warnings)
    if offsets.device_applied and offsets.device is not None:
        reference = recorded.with_body_offset(offsets.device.transform)
    clocked = offsets.clocked(estimate, notes)  # the association adds time_offset_s
    matched = associate(
        reference,
        clocked,
        method=config.association,
        max_dt_ns=round(config.max_dt_s * _NS_PER_S),
        max_gap_ns=round(config.max_gap_s * _NS_PER_S),
        offset_ns=round(offsets.time_offset_s * _NS_PER_S),
    )
    notes.extend(association_notes(matched, len(clocked), reference.loss_words))
    min_gap_ns = round(config.max_gap_s * _NS_PER_S)
    own_gaps = estimate.tracking_losses(min_gap_ns)
    if own_gaps:
        start, end = max(own_gaps, key=lambda gap: gap[1] - gap[0])
        after_s = (start - int(reference.stamps_ns[0])) / _NS_PER_S
        own_gap_s = gap_threshold_ns(estimate.stamps_ns, min_gap_ns=min_gap_ns) / _NS_PER_S
        own_loss = estimate.loss_words.replace("tracking loss", "its own tracking loss")
        notes.append(
            f"The estimate itself has {len(own_gaps)} {'gap' if len(own_gaps) == 1 else 'gaps'} "
            f"longer than {format_duration(own_gap_s)} "
            f"({own_loss}; the longest, {format_duration((end - start) / _NS_PER_S)}, starts "
            f"{format_duration(abs(after_s))} {'after' if after_s >= 0 else 'before'} the "
            "reference's first pose)."
        )
    alignment = align(
        matched.reference,
        matched.estimate,
        method=config.align,
        window=config.align_first,
        calibrate_at_s=config.calibrate_at_s,
    )
    notes.extend(alignment.warnings)
    aligned = matched.estimate.transformed(alignment.transform)
    ref = matched.reference
    if config.planar:  # x-y only: the estimate takes the reference's heights
        planar_xyz = aligned.positions_xyz.copy()
        planar_xyz[:, 2] = ref.positions_xyz[:, 2]
        aligned = replace(aligned, positions_xyz=planar_xyz)
    ate_t, ate_r = compute_ate(ref, aligned)
    if ate_r is None:
        side = "reference" if ref.quat_xyzw is None else "estimate"
        notes.append(f"Rotation errors not computed: the {side} has no orientations.")
    i, j = rpe_pairs(
        ref, delta=config.rpe_delta, unit=config.rpe_unit, all_pairs=config.rpe_all_pairs
    )
    rpe_t, rpe_r = compute_rpe(
        ref, aligned, delta=config.rpe_delta, unit=config.rpe_unit, pairs=(i, j)
    )
    drift = compute_drift(ref, aligned)
    t0_ns = int(reference.stamps_ns[0])  # every time in the result counts from here
    assessment = _assess(reference, ref, aligned, (ate_t, ate_r, rpe_t, rpe_r), config)
    notes.extend(() if assessment is None else assessment.warnings)
    verdict = None
    if config.tolerance is not None:
        judged = None if assessment is None else assessment.tolerance
        losses = reference.tracking_losses(min_gap_ns)
        breaks = path_breaks(ref.stamps_ns, min_gap_ns=min_gap_ns, losses=losses)
        verdict = tolerance_verdict_of(ate_t, ref, config.tolerance, t0_ns, judged, breaks=breaks)
    return EstimateResult(
        estimate=estimate,
        association=matched,
        alignment=alignment,
        aligned=aligned,
        ate_translation=ate_t,
        ate_rotation=ate_r,
        rpe_translation=rpe_t,
        rpe_rotation=rpe_r,
        rpe_index=np.stack([i, j], axis=1),
        drift=drift,
        within=share_within(ate_t, config.thresholds_m),
        worst=greatest_errors(ate_t, ref, count=config.worst_count, t0_ns=t0_ns),
        verdict=verdict,
        warnings=tuple(notes),
        offsets=offsets,
        assessment=assessment,
        notes=offsets.notes,
        excursions=find_excursions(
            reference.tracking_losses(min_gap_ns),
            clocked,
            alignment.transform,
            ref.stamps_ns,
            ate_t.values,
            min_excursion_s=config.min_excursion_s,
            offset_ns=matched.offset_ns,
        ),
    )


def _assess(
    reference: Trajectory,
    ref: Trajectory,
    aligned: Trajectory,
    series: tuple[ErrorSeries, ErrorSeries | None, ErrorSeries, ErrorSeries | None],
    config: EvaluationConfig,
) -> Assessment | None:
    """Return the intervals, NEES and reference-error check, or None when none applies."""
    sigma = config.reference_sigma_m
    if config.no_ci and aligned.cov6 is None and sigma is None and reference.cov6 is None:
        return None  # nothing to assess: no scipy loaded
    from loceval.assessment.assess import SERIES, assess  # noqa: PLC0415  (scipy)

    tolerance = config.tolerance
    return assess(
        reference=ref,
        aligned=aligned,
        series=dict(zip(SERIES, series, strict=True)),
        thresholds_m=config.thresholds_m,
        tolerance=None if tolerance is None else (tolerance.distance_m, tolerance.share),
        confidence=not config.no_ci,
        reference_sigma_m=sigma,
        full_reference=reference,
    )


def _stats(e: EstimateResult, name: str) -> dict[str, object] | None:
    """Return a STATS block with its 95 % intervals (``ci95`` null when not computed)."""
    series = getattr(e, name)
    if series is None:
        return None
    out: dict[str, object] = dict(series.stats.to_dict())
    found: IntervalStats | None = None if e.assessment is None else e.assessment.intervals.get(name)
    out["ci95"] = None if found is None else {k: list(v) for k, v in found.ci95.items()}
    out["n_effective"] = None if found is None else found.n_effective
    return out


def _within_ci95(e: EstimateResult) -> dict[str, list[float]] | None:
    found = None if e.assessment is None else e.assessment.intervals.get("ate_translation")
    if found is None:
        return None
    return {f"{t:g}": list(found.within_ci95[t]) for t in e.within}


def _estimate_dict(e: EstimateResult, config: EvaluationConfig, t0: int) -> dict[str, object]:
    matched = e.association
    return {
        "name": e.estimate.name,
        "system": e.system,
        "coverage": e.coverage,
        "source": e.estimate.source,
        "poses": len(e.estimate),
        "duration_s": e.estimate.duration_s,
        "length_m": e.estimate.length_m,
        "rate_hz": e.estimate.rate_hz,
        "matched": len(matched),
        "dropped": {
            "outside": matched.dropped_outside,
            "gap": matched.dropped_gap,
            "unmatched": matched.dropped_unmatched,
        },
        "time_offset_s": matched.offset_ns / _NS_PER_S,
        "time_offset": None if e.offsets is None else e.offsets.time_offset_dict(),
        "device_offset": None if e.offsets is None else e.offsets.device_offset_dict(),
        "alignment": e.alignment.to_dict(),
        "ate": {
            "translation_m": _stats(e, "ate_translation"),
            "rotation_deg": _stats(e, "ate_rotation"),
        },
        "rpe": {
            "delta": config.rpe_delta,
            "unit": config.rpe_unit.value,
            "all_pairs": config.rpe_all_pairs,
            "pairs": len(e.rpe_translation),
            "translation_m": _stats(e, "rpe_translation"),
            "rotation_deg": _stats(e, "rpe_rotation"),
        },
        "within": {f"{t:g}": share for t, share in e.within.items()},
        "within_ci95": _within_ci95(e),
        "worst": [w.to_dict() for w in e.worst],
        "drift_pct": None if e.drift is None else e.drift.stats.to_dict(),
        "verdict": None if e.verdict is None else e.verdict.to_dict(),
        "consistency": None if e.assessment is None else e.assessment.consistency_dict(),
        "reference_error": None if e.assessment is None else e.assessment.reference_error_dict(),
        "excursions": [x.to_dict(t0) for x in e.excursions],
        "warnings": list(e.warnings),
        "notes": [*e.estimate.notes, *e.notes],
    }
