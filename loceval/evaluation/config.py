"""The options of an evaluation, typed: :class:`EvaluationConfig` (the CLI's and the API's).

Part of :mod:`loceval.evaluation`, which re-exports it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from loceval.assessment.verdict import Tolerance
from loceval.calibration.offsets import DeviceSource
from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.metrics.pose_errors import RPEUnit
from loceval.options import DEFAULT_THRESHOLDS_M, check_option, choice_default, number_default
from loceval.registration.alignment import AlignMethod, AlignWindow
from loceval.registration.association import AssociationMethod

__all__ = ["EvaluationConfig"]

_RPE_UNIT_WORDS = {RPEUnit.FRAMES: "frames", RPEUnit.METRES: "metres", RPEUnit.SECONDS: "seconds"}

_DEFAULT_ASSOCIATION = AssociationMethod(choice_default("association"))
_DEFAULT_ALIGN = AlignMethod(choice_default("align"))
_DEFAULT_RPE_UNIT = RPEUnit(choice_default("rpe_unit"))


@dataclass(frozen=True, slots=True)
class EvaluationConfig:
    """Every option of an evaluation (the CLI's and the service's options).

    Attributes:
        association: how poses are matched in time.
        max_dt_s: nearest matching's tolerance, seconds.
        max_gap_s: longest reference interval bridged by interpolation, seconds.
        time_offset_s: added to every estimate's stamps, seconds.
        align: the alignment method.
        align_first: the leading window that estimates the alignment.
        calibrate_at_s: for ``calibrate``, seconds after the first matched pose.
        reference_offset: rigid-body -> sensor offset applied to the reference poses.
        rpe_delta: RPE step.
        rpe_unit: what the RPE step counts.
        rpe_all_pairs: every pose starts an RPE pair (default: consecutive segments).
        thresholds_m: distances for the "share within" figures.
        tolerance: the application tolerance for the verdict, if any.
        worst_count: how many greatest errors to list.
        no_ci: skip the confidence intervals and comparisons (their ``ci95`` is null).
        reference_sigma_m: the reference's own per-axis standard deviation, metres.
        auto_time_offset: apply the time offset estimated from the motion.
        clock_drift_ppm: how fast the estimates' clocks run against the reference's, ppm,
            applied with the time offset at each estimate's first pose.
        auto_clock_drift: apply the clock drift (and steps) estimated from the motion.
        auto_device: apply the device offset estimated from the motion to the reference.
        reference_offset_source: ``urdf`` (a URDF or ``/tf_static``) or ``given``.
        planar: measure position errors in x-y only (each matched estimate pose takes
            the reference's height after alignment), for 2D systems.
        min_excursion_s: the shortest reference loss that is an excursion, seconds.
        min_trial_coverage: the least share of the reference's duration a trial (an
            estimate of a named system) must track; less is a failed trial (tracking lost).
    """

    association: AssociationMethod = _DEFAULT_ASSOCIATION
    max_dt_s: float = number_default("max_dt_s")
    max_gap_s: float = number_default("max_gap_s")
    time_offset_s: float = number_default("time_offset_s")
    align: AlignMethod = _DEFAULT_ALIGN
    align_first: AlignWindow = field(default_factory=AlignWindow)
    calibrate_at_s: float | None = None
    reference_offset: SimilarityTransform | None = None
    rpe_delta: float = number_default("rpe_delta")
    rpe_unit: RPEUnit = _DEFAULT_RPE_UNIT
    rpe_all_pairs: bool = False
    thresholds_m: tuple[float, ...] = DEFAULT_THRESHOLDS_M
    tolerance: Tolerance | None = None
    worst_count: int = round(number_default("worst"))
    no_ci: bool = False
    reference_sigma_m: float | None = None
    auto_time_offset: bool = False
    auto_device: bool = False
    reference_offset_source: DeviceSource = "given"
    planar: bool = False
    min_excursion_s: float = number_default("min_excursion_s")
    clock_drift_ppm: float = number_default("clock_drift_ppm")
    auto_clock_drift: bool = False
    min_trial_coverage: float = number_default("min_trial_coverage")

    def __post_init__(self) -> None:
        """Check the values against the bounds of :data:`loceval.options.OPTIONS`.

        Raises:
            InputError: a value out of bounds; the error carries the option's key.
        """
        check_option("max_dt_s", self.max_dt_s, unit="seconds")
        if self.max_gap_s < 1e-9:  # the table's minimum, in the unit a user thinks in
            msg = f"The maximum gap must be at least 1 ns, got {self.max_gap_s!r} s."
            raise InputError(msg, option="max_gap_s")
        check_option("max_gap_s", self.max_gap_s, unit="seconds")
        check_option("time_offset_s", self.time_offset_s, unit="seconds")
        check_option("clock_drift_ppm", self.clock_drift_ppm, unit="ppm")
        if self.calibrate_at_s is not None:
            check_option("calibrate_at_s", self.calibrate_at_s, unit="seconds")
        check_option("rpe_delta", self.rpe_delta, unit=_RPE_UNIT_WORDS[self.rpe_unit])
        for threshold in self.thresholds_m:
            check_option("thresholds_m", threshold, unit="metres")
        check_option("worst", self.worst_count)
        check_option("min_excursion_s", self.min_excursion_s, unit="seconds")
        check_option("min_trial_coverage", self.min_trial_coverage)
        if self.reference_sigma_m is not None:
            check_option("reference_sigma_m", self.reference_sigma_m, unit="metres")
        if self.auto_device and self.reference_offset is not None:
            msg = "Give the device offset or have it estimated from the motion, not both."
            raise InputError(msg, option="device")

    def to_dict(self) -> dict[str, object]:
        """Return the options as JSON (for the report's provenance)."""
        return {
            "association": self.association.value,
            "max_dt_s": self.max_dt_s,
            "max_gap_s": self.max_gap_s,
            "time_offset_s": self.time_offset_s,
            "align": self.align.value,
            "align_first": str(self.align_first),
            "calibrate_at_s": self.calibrate_at_s,
            "reference_offset": None
            if self.reference_offset is None
            else self.reference_offset.to_dict(),
            "rpe_delta": self.rpe_delta,
            "rpe_unit": self.rpe_unit.value,
            "rpe_all_pairs": self.rpe_all_pairs,
            "thresholds_m": list(self.thresholds_m),
            "tolerance": None
            if self.tolerance is None
            else {"distance_m": self.tolerance.distance_m, "share": self.tolerance.share},
            "no_ci": self.no_ci,
            "reference_sigma_m": self.reference_sigma_m,
            "auto_time_offset": self.auto_time_offset,
            "auto_device": self.auto_device,
            "planar": self.planar,
            "min_excursion_s": self.min_excursion_s,
            "clock_drift_ppm": self.clock_drift_ppm,
            "auto_clock_drift": self.auto_clock_drift,
            "min_trial_coverage": self.min_trial_coverage,
        }
