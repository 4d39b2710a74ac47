"""A clock that drifts and steps: the time offset as a line along the run, with its jumps.

A clock that no PTP disciplines runs fast or slow by tens of ppm (crystals) and an NTP daemon
may step it by tens of milliseconds. The time offset to add to the estimate's stamp ``s`` is
then no constant but

``o(s) = o_0 + beta (s - s_0) + sum_k J_k [s >= s_k]``,

where ``s_0`` is the estimate's first stamp, ``beta`` the offset's slope (a clock ``r`` fast
in ppm gives ``beta = -r / (1 + r)``: it gains ``r`` µs of stamp per second), and ``J_k``
the change of the offset at the step ``s_k``. Estimated from the same motion as the offset
(:mod:`loceval.calibration.clock`), in four stages:

1. **Windows.** The run is cut into about :data:`TARGET_WINDOWS` windows of the estimate's
   clock (:data:`MIN_WINDOW_S` to :data:`MAX_WINDOW_S` long). Per window, the masked
   Pearson correlation of the motion signals at every lag within ``±search`` of the run's
   offset (batched FFTs, Padfield 2012, as the run's coarse search) gives a coarse offset.
2. **Fine.** Gauss-Newton on each window's offset, all windows at once: with orientations on
   both sides, the rotation residuals ``log((A X)^T X B)`` of one-second relative motions
   (the device rotation ``X`` of the run held); position-only, the positions against the
   reference with each window aligned by its own rigid (or similarity) transform (Umeyama,
   batched), the offset's Jacobian being the reference's velocity with the window's mean
   removed (the translation absorbs it). Huber weights; each window's sigma is its
   sandwich ``(sum J psi)^2 / (sum J^2 psi')^2``.
3. **Line and steps.** A weighted robust line (Huber IRLS) through the windows' offsets;
   steps are added one at a time where one explains the most (binary segmentation over
   the window boundaries) while the next is significant (:data:`STEP_Z` sigma). The
   covariance is the sandwich of the robust fit scaled by the windows' own scatter about
   the model (so a misjudged window sigma does not leak into the slope's), times Student's
   factor for the few degrees of freedom.
4. **Step times.** Around each step, every relative motion of the estimate is judged under
   the offset before, the offset after, and (straddling) both; the step time is the change
   point of least cost, and its sigma the half-width of the times within one unit of cost
   (the profile likelihood), at least the interval between two poses.

**What cannot be told.** The drift is found only where the motion is: windows without motion
(the signal varies less than the offset check needs), or on untracked stretches, carry no
offset and are left out; a step inside a motionless stretch is placed somewhere in it (its
sigma says how wide). A clock set back (a negative jump) makes the stamps of that interval
interleave; the readers sort them, and those poses cannot be told apart. A drift that
changes rate along the run (temperature) is fitted by its mean rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from loceval.calibration._drift_steps import (
    STEP_Z,
    Line,
    fit_with_steps,
    refine_step,
    robust_line,
)
from loceval.calibration._drift_windows import (
    Fine,
    PositionRows,
    RotationPairs,
    RowMaker,
    Rows,
    coarse_offsets,
    fine_offsets,
    motion_signals,
)
from loceval.calibration.clockmodel import (
    MAX_RATE_PPM,
    SIGNIFICANT_Z,
    ClockDrift,
    ClockModel,
    ClockStep,
    DriftWindows,
    rate_of_slope,
    slope_of_rate,
)
from loceval.calibration.common import NS_PER_S, PoseSampler
from loceval.calibration.motion import DriftSignals
from loceval.core.arrays import BoolArray, FloatArray
from loceval.core.quantities import plus_minus
from loceval.errors import InputError
from loceval.options import option
from loceval.trajectory import Trajectory

__all__ = [
    "MAX_RATE_PPM",
    "SIGNIFICANT_Z",
    "ClockDrift",
    "ClockModel",
    "ClockStep",
    "DriftSignals",
    "DriftVerdict",
    "DriftWindows",
    "check_clock_drift",
    "describe_rate",
    "describe_step",
    "drift_checkable",
    "estimate_clock_drift",
    "judge_drift",
    "rate_of_slope",
    "slope_of_rate",
]

MAX_STEP_S = 0.5
"""The largest step searched, seconds, beyond the drift's own span."""
TARGET_WINDOWS = 64
"""How many windows the run is cut into, if their length allows."""
MIN_WINDOW_S = 8.0
MAX_WINDOW_S = 120.0
MIN_WINDOWS = 8
"""Fewest windows with an offset for a drift (fewer: the run is too short or too still)."""


def drift_checkable(estimate: Trajectory) -> bool:
    """Whether the estimate's run is long enough for :func:`estimate_clock_drift` at all."""
    return estimate.duration_s >= MIN_WINDOWS * MIN_WINDOW_S


# ---------------------------------------------------------------------------------------------


def estimate_clock_drift(
    reference: Trajectory,
    estimate: Trajectory,
    *,
    offset_s: float,
    device_rotation: FloatArray | None,
    max_gap_ns: int,
    with_scale: bool = False,
    max_pairs: int = 40_000,
    given: ClockModel | None = None,
    signals: DriftSignals | None = None,
    rounds: int = 2,
) -> ClockDrift:
    """Estimate the drift (and steps) of the estimate's clock along the run.

    Args:
        reference: the ground truth.
        estimate: the system under evaluation, on its own clock.
        offset_s: the run's time offset
            (:func:`loceval.calibration.clock.estimate_time_offset`), about which the windows
            are searched.
        device_rotation: (3, 3) the device rotation of the run (orientations on both sides),
            None for position-only.
        max_gap_ns: the longest reference interval that is not a tracking loss.
        with_scale: position-only windows are aligned with a similarity (monocular).
        max_pairs: most relative motions (or poses, position-only) used (thinned evenly).
        given: a model to search the windows about (default: ``offset_s`` constant).
        signals: the motion signals, if the caller has them (else computed here).
        rounds: how often the device rotation (or lever arm) is fitted again and the windows
            with it (2 when the drift is to be applied; 1 does for a check).

    Returns:
        The rate, the offset at the first pose and the steps, with sigmas and the windows.

    Raises:
        InputError: the run is too short, or too few windows have motion, to tell a drift.
    """
    epoch_ns = int(estimate.stamps_ns[0])
    duration_s = (int(estimate.stamps_ns[-1]) - epoch_ns) / NS_PER_S
    count = int(
        duration_s // float(np.clip(duration_s / TARGET_WINDOWS, MIN_WINDOW_S, MAX_WINDOW_S))
    )
    if count < MIN_WINDOWS:
        msg = (
            f"{estimate.name!r} lasts {duration_s:.0f} s, too short to tell a clock drift "
            f"(it needs {MIN_WINDOWS} stretches of {MIN_WINDOW_S:g} s); give the drift (0 ppm)."
        )
        raise InputError(msg, option="clock_drift_ppm")
    window_s = duration_s / count
    prior = given or ClockModel(offset_s=offset_s, epoch_ns=epoch_ns)
    sampler = PoseSampler.from_start(reference, max_gap_ns=max_gap_ns)
    search_s = MAX_STEP_S + MAX_RATE_PPM * 1e-6 * duration_s
    middles: FloatArray = (np.arange(count, dtype=np.float64) + 0.5) * window_s
    prior_s = prior.offsets_s(epoch_ns + np.rint(middles * NS_PER_S).astype(np.int64))
    coarse = coarse_offsets(
        reference,
        estimate,
        prior_s,
        signals or motion_signals(reference, estimate, max_gap_ns=max_gap_ns),
        window_s=window_s,
        search_s=search_s,
    )
    mid_ns = epoch_ns + round(0.5 * duration_s * NS_PER_S)
    maker = RowMaker(
        sampler,
        device_rotation,
        offset_ns=round(float(prior.offsets_s(np.array([mid_ns]))[0]) * NS_PER_S),
        with_scale=with_scale,
    )
    rows = maker.make(estimate, max_pairs)
    uniform = epoch_ns + np.rint(np.arange(1, count) * window_s * NS_PER_S).astype(np.int64)
    start = np.where(np.isfinite(coarse), coarse, prior_s)
    ref_t0_ns = int(reference.stamps_ns[0])
    # Pass 1: one constant offset per window; a first line.
    fine = fine_offsets(rows, uniform, epoch_ns, start)
    line = _checked_line(fine, estimate, window_s=window_s, detect=True)
    # Pass 2: each window's offset follows the line within it, so that it holds at the
    # window's middle whatever the spread of the motion in it (a constant offset per window
    # holds where its relative motions say most, which the rate then turns into a bias of
    # the offset at the first pose: 0.1 ms at 200 ppm). With orientations, the device
    # rotation is fitted again first, to offsets that follow the line, and once more after
    # (the first line, from the run's rotation, can be off by milliseconds, which leaves
    # the rotation a few hundredths of a degree off, and the rate a few tenths of a sigma).
    for _round in range(max(rounds, 1)):
        if isinstance(rows, RotationPairs):
            rows.refine_rotation(*_line_offsets(rows, line, epoch_ns))
            maker.rotation = rows.rotation
        elif isinstance(rows, PositionRows):
            rows.refine_lever(_line_offsets(rows, line, epoch_ns)[0], uniform)
            maker.lever = rows.lever
        fine = fine_offsets(
            rows, uniform, epoch_ns, line.at(middles), slope=line.coef[1], centre_s=middles
        )
        line = _checked_line(fine, estimate, window_s=window_s, detect=True)
    steps = [
        refine_step(maker, estimate, line, k, window_s=window_s, ref_t0_ns=ref_t0_ns)
        for k in range(len(line.breaks_s))
    ]
    if steps:
        # Pass 3: the windows cut at the steps, so that none straddles one.
        cuts = np.array([stamp for stamp, _ in steps], dtype=np.int64)
        far = np.min(np.abs(uniform[:, None] - cuts[None, :]), axis=1) > 0.25 * window_s * 1e9
        bounds = np.sort(np.concatenate((uniform[far], cuts)))
        edges = np.concatenate(([epoch_ns], bounds, [int(estimate.stamps_ns[-1])]))
        middles = (0.5 * (edges[:-1] + edges[1:] - 2 * epoch_ns) / NS_PER_S).astype(np.float64)
        breaks = tuple((stamp - epoch_ns) / NS_PER_S for stamp, _ in steps)
        line = replace(line, breaks_s=breaks)
        fine = fine_offsets(
            rows, bounds, epoch_ns, line.at(middles), slope=line.coef[1], centre_s=middles
        )
        line = _checked_line(fine, estimate, window_s=window_s, detect=False, breaks_s=breaks)
        steps = [
            refine_step(maker, estimate, line, k, window_s=window_s, ref_t0_ns=ref_t0_ns)
            for k in range(len(line.breaks_s))
        ]
    slope, sigma_slope = float(line.coef[1]), math.sqrt(line.cov[1, 1])
    return ClockDrift(
        rate_ppm=rate_of_slope(slope),
        sigma_rate_ppm=sigma_slope * 1e6 / (1.0 + slope) ** 2,
        offset_s=float(line.coef[0]),
        sigma_offset_s=math.sqrt(line.cov[0, 0]),
        epoch_ns=epoch_ns,
        duration_s=duration_s,
        steps=tuple(_step(line, k, stamp, span) for k, (stamp, span) in enumerate(steps)),
        windows=DriftWindows(fine.centre_s, fine.offset_s, fine.sigma_s, _used(fine, line)),
        scatter=line.scale,
    )


def _used(fine: Fine, line: Line) -> BoolArray:
    """Which windows the line used at full weight."""
    out = np.zeros(fine.offset_s.shape, dtype=bool)
    out[np.flatnonzero(fine.has_offset)] = line.weights >= 0.999
    return out


def _line_offsets(rows: Rows, line: Line, epoch_ns: int) -> tuple[FloatArray, FloatArray]:
    """The line's offsets at the rows' two ends."""
    since_i = (rows.stamp_i - np.int64(epoch_ns)).astype(np.float64) / NS_PER_S
    since_j = (rows.stamp_j - np.int64(epoch_ns)).astype(np.float64) / NS_PER_S
    return line.at(since_i), line.at(since_j)


def _checked_line(
    fine: Fine,
    estimate: Trajectory,
    *,
    window_s: float,
    detect: bool,
    breaks_s: tuple[float, ...] = (),
) -> Line:
    """The robust line through the windows with an offset (steps found or given).

    Raises:
        InputError: fewer than MIN_WINDOWS windows have an offset.
    """
    ok = fine.has_offset
    if ok.sum() < MIN_WINDOWS:
        msg = (
            f"Only {int(ok.sum())} of {ok.shape[0]} stretches of {window_s:.0f} s of "
            f"{estimate.name!r} move enough (and lie on tracked reference) to measure the time "
            "offset, too few to tell a clock drift; give the drift (0 ppm)."
        )
        raise InputError(msg, option="clock_drift_ppm")
    c, o, sigma = fine.centre_s[ok], fine.offset_s[ok], fine.sigma_s[ok]
    if detect:
        return fit_with_steps(c, o, sigma, window_s=window_s)
    line = robust_line(c, o, sigma, breaks_s)
    while line.breaks_s:  # a step the second pass no longer tells apart is dropped
        z = np.abs(line.coef[2:]) / np.sqrt(np.diag(line.cov)[2:])
        weakest = int(np.argmin(z))
        if z[weakest] > STEP_Z:
            break
        line = robust_line(c, o, sigma, line.breaks_s[:weakest] + line.breaks_s[weakest + 1 :])
    return line


def _step(line: Line, k: int, stamp_ns: int, span: tuple[float, float]) -> ClockStep:
    """Step ``k`` of the line, found at ``stamp_ns``.

    ``span`` is when it happened (ns after the reference's first pose) and its 1-sigma (ns).
    """
    at_ns, sigma_ns = span
    return ClockStep(
        stamp_ns=stamp_ns,
        at_s=at_ns / NS_PER_S,
        sigma_at_s=sigma_ns / NS_PER_S,
        size_s=float(line.coef[2 + k]),
        sigma_size_s=math.sqrt(line.cov[2 + k, 2 + k]),
    )


# --- what the evaluation makes of it ----------------------------------------------------------


def describe_rate(rate_ppm: float, sigma_ppm: float | None = None) -> str:
    """Words for a rate: ``"runs 50.02 ± 0.03 ppm fast"``."""
    way = "fast" if rate_ppm >= 0 else "slow"
    return f"runs {plus_minus(abs(rate_ppm), sigma_ppm, 'ppm', places=2)} {way}"


def describe_step(step: ClockStep) -> str:
    """Words for a step: ``"at 300.02 ± 0.01 s its clock jumped ahead by 80.0 ± 0.2 ms"``."""
    way = "ahead" if step.size_s < 0 else "back"
    return (
        f"at {plus_minus(step.at_s, step.sigma_at_s, 's')} its clock jumped {way} by "
        f"{plus_minus(abs(step.size_s) * 1e3, step.sigma_size_s * 1e3, 'ms')}"
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class DriftVerdict:
    """What the evaluation applies of a clock's drift, and what it tells the user.

    Attributes:
        rate_ppm: the rate applied (0: none).
        steps_applied: the steps found are applied.
        offset_s: with the drift applied, the data's offset at the estimate's first pose
            (None: the run's constant offset stands).
        sigma_offset_s: its 1-sigma.
        warnings: sentences that ask something of the user.
        notes: sentences for information.
    """

    rate_ppm: float
    steps_applied: bool
    offset_s: float | None
    sigma_offset_s: float | None
    warnings: tuple[str, ...]
    notes: tuple[str, ...]


def judge_drift(
    drift: ClockDrift,
    *,
    given_rate_ppm: float | None,
    tolerance_s: float,
    option_hint: str,
) -> DriftVerdict:
    """Decide what of ``drift`` to apply, and say so.

    ``given_rate_ppm`` None (``auto``): the rate is applied when significant
    (:data:`SIGNIFICANT_Z` sigma), and the steps found with it (a line with its steps is one
    model); else nothing is. Given (0 by default): the given rate is applied and the data
    only check it: a drift from it, or a step, that moves the offset by more than
    ``tolerance_s`` over the run is a warning that names ``option_hint`` (how to set the
    option); a smaller but significant one is a note.
    """
    over = f"over the {drift.duration_s / 60.0:.1f} min run"
    rate_words = describe_rate(drift.rate_ppm, drift.sigma_rate_ppm)
    steps = "; ".join(describe_step(s) for s in drift.steps)
    stepped = f"; {steps}" if steps else ""
    if given_rate_ppm is None:
        if drift.significant or drift.steps:
            words = (
                f"Clock drift estimated and applied: the estimate's clock {rate_words} "
                f"(the time offset moves by {drift.moved_s * 1e3:.1f} ms {over}){stepped}."
            )
            return DriftVerdict(
                rate_ppm=drift.rate_ppm,
                steps_applied=bool(drift.steps),
                offset_s=drift.offset_s,
                sigma_offset_s=drift.sigma_offset_s,
                warnings=(words,),
                notes=(),
            )
        note = (
            f"No clock drift to apply: the estimate's clock {rate_words} against the ground "
            "truth's, which is not significant."
        )
        return DriftVerdict(
            rate_ppm=0.0,
            steps_applied=False,
            offset_s=None,
            sigma_offset_s=None,
            warnings=(),
            notes=(note,),
        )
    off_s = abs(slope_of_rate(drift.rate_ppm) - slope_of_rate(given_rate_ppm)) * drift.duration_s
    sigma = drift.sigma_rate_ppm
    warnings: list[str] = []
    notes: list[str] = []
    if abs(drift.rate_ppm - given_rate_ppm) > SIGNIFICANT_Z * sigma:
        against = "" if given_rate_ppm == 0 else f" (you gave {given_rate_ppm:g} ppm)"
        told = (
            f"The estimate's clock {rate_words}{against}, so the time offset moves by "
            f"{off_s * 1e3:.1f} ms {over}"
        )
        if off_s > tolerance_s:
            warnings.append(
                f"{told}, more than the {tolerance_s * 1e3:g} ms association tolerance; "
                f"{option_hint} to correct it."
            )
        else:
            notes.append(
                f"{told}, within the {tolerance_s * 1e3:g} ms association tolerance; not corrected."
            )
    for step in drift.steps:
        told = f"The estimate's clock steps: {describe_step(step)}"
        if abs(step.size_s) > tolerance_s:
            warnings.append(
                f"{told}, more than the {tolerance_s * 1e3:g} ms association tolerance; "
                f"{option_hint} to correct it."
            )
        else:
            notes.append(f"{told}, within the association tolerance; not corrected.")
    return DriftVerdict(
        rate_ppm=given_rate_ppm,
        steps_applied=False,
        offset_s=None,
        sigma_offset_s=None,
        warnings=tuple(warnings),
        notes=tuple(notes),
    )


def check_clock_drift(
    reference: Trajectory,
    estimate: Trajectory,
    prior: ClockModel,
    rotation: FloatArray | None,
    *,
    given_rate_ppm: float | None,
    tolerance_s: float,
    max_gap_ns: int,
    with_scale: bool,
    max_rows: int,
    signals: DriftSignals | None,
) -> tuple[ClockDrift | None, DriftVerdict]:
    """The drift of the estimate's clock and what to apply of it (None: not checked).

    What :func:`loceval.calibration.clock.estimate_time_offset` runs after the run's
    offset (``prior``: that offset at the first pose, with the given rate). A drift asked
    for (``given_rate_ppm`` None) that cannot be told raises; a mere check that cannot run
    says why in a note, unless the run is too short for any (then it is silent).

    Raises:
        InputError: ``auto``, and the run is too short or too still to tell a drift.
    """
    given = given_rate_ppm or 0.0
    try:
        drift = estimate_clock_drift(
            reference,
            estimate,
            offset_s=prior.offset_s,
            device_rotation=rotation,
            max_gap_ns=max_gap_ns,
            with_scale=with_scale,
            max_pairs=max_rows,
            given=prior,
            signals=signals,
            rounds=2 if given_rate_ppm is None else 1,
        )
    except InputError as err:
        if given_rate_ppm is None:
            raise
        notes: tuple[str, ...] = ()
        if drift_checkable(estimate):
            notes = (f"The clock's drift could not be checked against the motion: {err}",)
        return None, DriftVerdict(
            rate_ppm=given,
            steps_applied=False,
            offset_s=None,
            sigma_offset_s=None,
            warnings=(),
            notes=notes,
        )
    spec = option("clock_drift_ppm")
    verdict = judge_drift(
        drift,
        given_rate_ppm=given_rate_ppm,
        tolerance_s=tolerance_s,
        option_hint=f"set {spec.words} to auto ({spec.flag} auto, or {spec.key}: auto)",
    )
    return drift, verdict
