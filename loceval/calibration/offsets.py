"""The evaluation's clock and device-offset check: estimate both from the motion, per estimate.

:func:`check_offsets` is what :func:`loceval.evaluation.evaluate` runs for each estimate:

- **Time offset**: always estimated (:func:`loceval.calibration.clock.estimate_time_offset`).
  Given a value (0 by default), the value is applied and the data only check it (a warning
  when they disagree beyond 3 sigma and a few ms); ``auto`` applies the estimate (the
  candidate nearest 0 when the motion repeats). A check that cannot run (too few poses, no
  motion) becomes a warning, never a failure; an ``auto`` that cannot run fails with the
  reason.
- **Clock drift**: checked alike on runs long enough (:mod:`loceval.calibration.drift`); a
  given rate (0 by default) is applied, ``auto`` applies the estimated rate and steps when
  significant. The offset is then a line along the run (:attr:`OffsetCheck.clock`), whose
  value at the estimate's first pose is ``time_offset_s``.
- **Device offset**: ``auto`` estimates it
  (:func:`loceval.calibration.handeye.estimate_device_offset`)
  jointly with the time offset and applies it to the reference; a given one (``offset``,
  URDF, ``/tf_static``) is applied and compared with the estimate from the motion when
  both sides have orientations. Position-only systems get the time offset only.

The check's cost is bounded: the correlation grid is at most 2**19 samples and the least
squares of a mere check use at most :data:`CHECK_MAX_PAIRS` relative motions (about 0.15 s
of CPU on 200,000 reference against 50,000 estimate poses). scipy is imported on first use.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, TypeVar

import numpy as np

from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError, LocevalError
from loceval.trajectory import MAX_OFFSET_M

if TYPE_CHECKING:
    from loceval.calibration.clock import TimeOffsetEstimate
    from loceval.calibration.clockmodel import ClockModel
    from loceval.calibration.handeye import DeviceOffsetComparison, DeviceOffsetEstimate
    from loceval.trajectory import Trajectory

__all__ = ["CHECK_MAX_PAIRS", "DeviceSource", "OffsetCheck", "check_offsets", "parse_offset"]

CHECK_MAX_PAIRS = 1_000
"""Most relative motions the least squares use when the result only checks a given value."""
ESTIMATE_MAX_PAIRS = 3_000
"""... and when the result is applied (``auto``)."""

DeviceSource = Literal["given", "urdf"]
"""Where a given device offset comes from: typed numbers, or a URDF / a bag's ``/tf_static``."""

_T = TypeVar("_T")
_APPLIED_NOTE = "Time offset estimated and applied:"
_CHECK_ERRORS = (LocevalError, ValueError, ArithmeticError)
"""What a mere check turns into a warning (numerical trouble included: never fail for it)."""


@dataclass(frozen=True, slots=True, eq=False)
class OffsetCheck:
    """The time and device offsets of one estimate: given, estimated, applied.

    Attributes:
        time_offset_s: the time offset applied to the estimate's stamps, seconds.
        time_offset: what the data say about it (None: the check could not run).
        device_given: the device offset given (body -> sensor), if any.
        device_source: where the given one comes from.
        device: the device offset estimated from the motion (applied when ``auto``).
        device_applied: the estimated device offset is the one applied.
        comparison: how far the estimate is from the given one (both present).
        warnings: sentences for the user.
        clock_drift_ppm: the clock rate applied when the clock was not checked (given).
        notes: sentences for information (nothing to do).
    """

    time_offset_s: float
    time_offset: TimeOffsetEstimate | None
    device_given: SimilarityTransform | None = None
    device_source: DeviceSource = "given"
    device: DeviceOffsetEstimate | None = None
    device_applied: bool = False
    comparison: DeviceOffsetComparison | None = None
    warnings: tuple[str, ...] = ()
    clock_drift_ppm: float = 0.0
    notes: tuple[str, ...] = ()

    def clocked(self, estimate: Trajectory, notes: list[str]) -> Trajectory:
        """``estimate`` with the offset's change along the run added to its stamps.

        The association then adds ``time_offset_s`` (the offset at the first pose) to all.
        Poses that a step puts among those before it are dropped, with a note.
        """
        clocked = self.clock(estimate).restamped(estimate)
        if len(clocked) < len(estimate):
            notes.append(
                f"{len(estimate) - len(clocked)} poses of the estimate were dropped: with the "
                "clock's step applied, their stamps fall among those of the poses before it "
                "(a clock set back, or a step whose time the motion tells only roughly)."
            )
        return clocked

    def clock(self, estimate: Trajectory) -> ClockModel:
        """The time offset applied along ``estimate``'s run (its first stamp the epoch)."""
        from loceval.calibration.clockmodel import ClockModel  # noqa: PLC0415

        if self.time_offset is not None:
            return dataclasses.replace(self.time_offset.model, offset_s=self.time_offset_s)
        return ClockModel(
            offset_s=self.time_offset_s,
            epoch_ns=int(estimate.stamps_ns[0]),
            rate_ppm=self.clock_drift_ppm,
        )

    def time_offset_dict(self) -> dict[str, object]:
        """Return the contract's ``time_offset`` object."""
        if self.time_offset is not None:
            return self.time_offset.to_dict()
        return {
            "value_s": self.time_offset_s,
            "sigma_s": None,
            "source": "given",
            "estimated_s": None,
            "candidates_s": [],
            "rate_ppm": self.clock_drift_ppm,
            "rate_source": "given",
            "estimated_rate_ppm": None,
            "sigma_rate_ppm": None,
            "steps": [],
        }

    def device_offset_dict(self) -> dict[str, object] | None:
        """Return the contract's ``device_offset`` object (None: none given or estimated)."""
        if self.device_applied and self.device is not None:
            return self.device.to_dict()
        if self.device_given is None:
            return None
        return {
            "translation_m": [float(v) for v in self.device_given.translation],
            "rotation_xyzw": _quat_of(self.device_given),
            "sigma_translation_m": [None, None, None],
            "sigma_rotation_deg": [None, None, None],
            "source": self.device_source,
            "unobservable": [],
        }


def _quat_of(transform: SimilarityTransform) -> list[float]:
    from loceval.core.rotation import Rotation  # noqa: PLC0415

    return [float(v) for v in Rotation.from_matrix(transform.rotation).as_quat()]


def _unstamped(
    names: list[str],
    time_offset_s: float | None,
    device: SimilarityTransform | None,
    device_source: DeviceSource,
    clock_drift_ppm: float | None,
) -> OffsetCheck:
    """The check of a pair one of which has pose numbers for stamps: nothing to check.

    Raises:
        InputError: the time offset was asked to be estimated (``auto``), or a clock drift
            given or asked for.
    """
    which = " and ".join(repr(n) for n in names)
    have = "has" if len(names) == 1 else "have"
    if clock_drift_ppm is None or clock_drift_ppm != 0.0:
        msg = (
            f"{which} {have} no times (poses are numbered, as a KITTI file without its times "
            "file), so no clock drift can be estimated or applied; give the times file "
            "(kitti:PATH@times=TIMES) or a clock drift of 0."
        )
        raise InputError(msg, option="clock_drift_ppm")
    if time_offset_s is None:
        msg = (
            f"{which} {have} no times (poses are numbered, as a KITTI file without its times "
            "file), so no time offset can be estimated; give the times file "
            "(kitti:PATH@times=TIMES) or a time offset of 0."
        )
        raise InputError(msg, option="time_offset_s")
    note = (
        f"{which} {have} no times (poses are numbered, as a KITTI file without its times file): "
        "poses are matched by number and the clocks are not checked."
    )
    return OffsetCheck(
        time_offset_s=float(time_offset_s),
        time_offset=None,
        device_given=device,
        device_source=device_source,
        warnings=(note,),
    )


def check_offsets(
    reference: Trajectory,
    estimate: Trajectory,
    *,
    time_offset_s: float | None,
    device: SimilarityTransform | None = None,
    device_source: DeviceSource = "given",
    auto_device: bool = False,
    max_gap_s: float,
    with_scale: bool = False,
    clock_drift_ppm: float | None = 0.0,
    tolerance_s: float = 0.01,
) -> OffsetCheck:
    """Estimate the time (and device) offset of one estimate; check or apply them.

    Args:
        reference: the ground truth as recorded (the tracked body, no device offset).
        estimate: the system under evaluation.
        time_offset_s: the given time offset, seconds; None estimates and applies it.
        device: the given device offset (body -> sensor), checked against the motion.
        device_source: where ``device`` comes from.
        auto_device: estimate the device offset and apply it (``device`` must be None).
        max_gap_s: longest reference interval that is not a tracking loss, seconds.
        with_scale: the estimate has its own scale (monocular; Sim(3) alignment).
        clock_drift_ppm: the given clock rate, ppm (applied and checked); None estimates it
            and applies it (and its steps) when significant.
        tolerance_s: the association's tolerance (a drift not applied that moves the offset
            by more over the run is a warning).

    Returns:
        What was given, estimated and applied, with the warnings.

    Raises:
        InputError: an estimate asked for (``auto``) cannot be made from these data.
        AssociationError: ``auto`` and the motions match at no time offset.
    """
    from loceval.calibration.clock import describe_offset, estimate_time_offset  # noqa: PLC0415

    auto_time = time_offset_s is None
    notes: list[str] = []
    pair = ((reference, "the reference"), (estimate, "the estimate"))
    numbered = [t.name or role for t, role in pair if t.indexed]
    if numbered:
        return _unstamped(numbered, time_offset_s, device, device_source, clock_drift_ppm)
    clock = _estimated(
        lambda: estimate_time_offset(
            reference,
            estimate,
            given_offset_s=time_offset_s,
            clock_drift_ppm=clock_drift_ppm,
            tolerance_s=tolerance_s,
            max_gap_s=max_gap_s,
            with_scale=with_scale,
            max_pairs=ESTIMATE_MAX_PAIRS if auto_time else CHECK_MAX_PAIRS,
        ),
        applied=auto_time or clock_drift_ppm is None,
        what="time offset",
        notes=notes,
    )
    applied_s = clock.value_s if clock is not None else float(time_offset_s or 0.0)
    if clock is not None:
        notes.extend(clock.warnings)
    check = OffsetCheck(
        time_offset_s=applied_s,
        time_offset=clock,
        device_given=device,
        device_source=device_source,
        clock_drift_ppm=clock_drift_ppm or 0.0,
        notes=() if clock is None else clock.notes,
    )
    if not (auto_device or device is not None):
        return dataclasses.replace(check, warnings=tuple(notes))
    # The device offset is estimated on the clock the data show (their offset, drift and
    # steps), whatever is applied: a given offset or a drift not applied that the data
    # contradict would bend the relative motions, and with them the device offset, beyond
    # its sigma (a ground robot's rotation about its only axis most). The offset is refined
    # jointly; the refined one is applied only when it is the one applied (``auto``).
    data_clock = _data_clock(clock) or check.clock(estimate)
    applied_clock = check.clock(estimate)
    same_shape = (data_clock.rate_ppm, data_clock.steps) == (
        applied_clock.rate_ppm,
        applied_clock.steps,
    )
    estimate = data_clock.restamped(estimate)
    if not (reference.has_orientation and estimate.has_orientation):
        if auto_device:
            side = reference.name if not reference.has_orientation else estimate.name
            notes.append(
                f"{side!r} has no orientations, so the device offset is not estimated and "
                "none is applied (a position-only system gets the time offset only)."
            )
        return dataclasses.replace(check, warnings=tuple(notes))
    found = _device(
        reference,
        estimate,
        data_clock.offset_s,
        auto_device=auto_device,
        max_gap_s=max_gap_s,
        with_scale=with_scale,
        notes=notes,
    )
    if found is None:
        return dataclasses.replace(check, warnings=tuple(notes))
    if not auto_device:
        from loceval.calibration.handeye import compare_device_offset  # noqa: PLC0415

        assert device is not None  # noqa: S101  (auto_device or device, checked above)
        given = "URDF or /tf_static link" if device_source == "urdf" else "given device offset"
        comparison = compare_device_offset(found, device, given_source=given)
        notes.append(comparison.message)
        return dataclasses.replace(
            check, device=found, comparison=comparison, warnings=tuple(notes)
        )
    notes.extend(found.warnings)
    t_mm = ", ".join(f"{v * 1e3:.1f}" for v in found.translation_m)
    notes.append(
        f"Device offset estimated from the motion and applied to the reference: ({t_mm}) mm "
        f"from the tracked body to the sensor, from {found.pairs} relative motions."
    )
    if auto_time and same_shape and clock is not None and found.sigma_time_offset_s is not None:
        # The joint fit refines the clock's estimate with the device offset: apply that.
        clock = _with_joint(clock, found.time_offset_s, found.sigma_time_offset_s)
        applied_s = clock.value_s
        notes = [n for n in notes if not n.startswith(_APPLIED_NOTE)]
        notes.append(
            f"{_APPLIED_NOTE} {describe_offset(applied_s, clock.sigma_s)} (jointly with the "
            "device offset)."
        )
    return dataclasses.replace(
        check,
        time_offset_s=applied_s,
        time_offset=clock,
        device=found,
        device_applied=True,
        warnings=tuple(notes),
    )


def _device(
    reference: Trajectory,
    estimate: Trajectory,
    time_offset_s: float,
    *,
    auto_device: bool,
    max_gap_s: float,
    with_scale: bool,
    notes: list[str],
) -> DeviceOffsetEstimate | None:
    """Estimate the device offset with the time offset; None (a note) if a check cannot run."""
    from loceval.calibration.handeye import estimate_device_offset  # noqa: PLC0415

    return _estimated(
        lambda: estimate_device_offset(
            reference,
            estimate,
            time_offset_s=time_offset_s,
            fit_time_offset=True,
            with_scale=with_scale,
            max_gap_s=max_gap_s,
            max_pairs=ESTIMATE_MAX_PAIRS if auto_device else CHECK_MAX_PAIRS,
        ),
        applied=auto_device,
        what="device offset",
        notes=notes,
    )


def _estimated(
    estimate: Callable[[], _T], *, applied: bool, what: str, notes: list[str]
) -> _T | None:
    """Return ``estimate()``; if it fails and would only check a given value, None and a note.

    An estimate that is to be applied (``auto``) raises its error instead.
    """
    try:
        return estimate()
    except _CHECK_ERRORS as err:
        if applied:
            raise
        notes.append(f"The {what} could not be checked against the motion: {err}")
        return None


def _data_clock(clock: TimeOffsetEstimate | None) -> ClockModel | None:
    """The clock the data show: their offset, with the drift and steps when significant."""
    if clock is None or clock.estimated_s is None:
        return None
    drift = clock.drift
    if drift is not None and (drift.significant or drift.steps):
        return drift.model(with_rate=True, with_steps=True, offset_s=drift.offset_s)
    return dataclasses.replace(clock.model, offset_s=clock.estimated_s, rate_ppm=clock.rate_ppm)


def _with_joint(clock: TimeOffsetEstimate, value_s: float, sigma_s: float) -> TimeOffsetEstimate:
    """Return the clock's estimate with the jointly refined value in place of the chosen one."""
    chosen = clock.estimated_s if clock.estimated_s is not None else value_s
    candidates = sorted(value_s if c == chosen else c for c in clock.candidates_s)
    return dataclasses.replace(
        clock,
        value_s=value_s,
        sigma_s=sigma_s,
        estimated_s=value_s,
        candidates_s=tuple(candidates),
    )


def parse_offset(text: str) -> SimilarityTransform:
    """Parse ``"x y z qx qy qz qw"`` (or ``"x y z"``) into a rigid offset.

    Raises:
        InputError: not 3 or 7 finite numbers, x y z over MAX_OFFSET_M, a non-unit quaternion.
    """
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) not in (3, 7) or not np.isfinite(values).all():
        msg = (
            f'The device offset takes "x y z qx qy qz qw" in metres and a unit quaternion '
            f'(or just "x y z"), got {text!r}.'
        )
        raise InputError(msg, option="offset")
    if float(np.abs(values[:3]).max()) > MAX_OFFSET_M:
        msg = f"The device offset's x y z {values[:3]!r} exceed ±{MAX_OFFSET_M:g} m; give metres."
        raise InputError(msg, option="offset")
    quat = np.array(values[3:] if len(values) == 7 else [0.0, 0.0, 0.0, 1.0])
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > 1e-3:
        msg = f"The device offset's quaternion must be unit (x y z w), its norm is {norm:.6g}."
        raise InputError(msg, option="offset")
    return SimilarityTransform.from_pose(np.array(values[:3]), quat / norm)
