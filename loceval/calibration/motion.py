"""The motion signals both clocks are compared by, and their correlation at every lag.

The time offset's coarse search (:func:`coarse_search`, the first stage of
:mod:`loceval.calibration.clock`) and the clock drift's windows (:mod:`loceval.calibration.drift`)
correlate these: the angular speed of each trajectory from its orientations (or its speed from
positions when either side is position-only), sampled every ``dt_s`` from its first pose, gaps
masked.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from loceval.calibration.common import NS_PER_S, PoseSampler, rotvec_of
from loceval.core.arrays import BoolArray, FloatArray
from loceval.core.geometry import compose_quat, conjugate_quat
from loceval.core.norms import row_norms
from loceval.errors import AssociationError, InputError
from loceval.trajectory import Trajectory

__all__ = [
    "CANDIDATE_SHARE",
    "MIN_SAMPLES",
    "CoarseSearch",
    "DriftSignals",
    "MotionSignal",
    "coarse_search",
    "grid_dt_s",
    "motion_signal",
]

CANDIDATE_SHARE = 0.9
"""A correlation peak within this share of the best one is a candidate offset."""
AMBIGUITY_NOISE_SHARE = 0.5
"""... and falls short of it by at most this share of the best one's own shortfall from 1
(plus 0.02): noise lowers every peak alike, a different motion lowers one more."""
MIN_OVERLAP_SHARE = 0.5
"""Lags are searched where the overlap holds at least this share of the shorter signal."""
MIN_CANDIDATE_SEPARATION_S = 1.0
"""Peaks closer than this to a higher one belong to it (the peak's own width)."""
MIN_CORRELATION = 0.2
"""Below this best correlation the motions do not match at any offset."""
WEAK_CORRELATION = 0.5
"""Below this best correlation the result carries a warning."""
_MIN_ANGULAR_STD_RAD_S = np.radians(0.5)
_MIN_SPEED_STD_M_S = 0.002
MIN_SAMPLES = 20
"""Fewest poses (or valid grid samples) the offset's estimate works with."""


class MotionSignal(StrEnum):
    """The signal that was correlated."""

    ANGULAR_SPEED = "angular_speed"
    SPEED = "speed"


@dataclass(frozen=True, slots=True, eq=False)
class DriftSignals:
    """The motion signals of both sides on one grid (from the run's coarse search).

    Attributes:
        reference: (F,) the reference's signal from its first pose, every ``dt_s``.
        reference_mask: (F,) where it is valid.
        estimate: (G,) the estimate's, from its first stamp (its clock).
        estimate_mask: (G,) where it is valid.
        dt_s: the grid's step, seconds.
    """

    reference: FloatArray
    reference_mask: BoolArray
    estimate: FloatArray
    estimate_mask: BoolArray
    dt_s: float


# --- stage 1: the windows' coarse offsets -----------------------------------------------------


def grid_dt_s(reference: Trajectory, estimate: Trajectory) -> float:
    """The step of the motion signals' grid, seconds (the slower rate's interval, bounded)."""
    rate = min(reference.rate_hz, estimate.rate_hz)
    dt = float(np.clip(1.0 / rate if rate > 0 else 0.05, 0.04, 0.1))
    span = max(reference.duration_s, estimate.duration_s)
    return max(dt, span / 2**19)  # bounds the FFT length on day-long recordings


def motion_signal(
    trajectory: Trajectory, signal: MotionSignal, *, dt_s: float, max_gap_ns: int
) -> tuple[FloatArray, BoolArray]:
    """Return a trajectory's motion signal on a grid of ``dt_s`` from its first pose.

    The value at grid point k is the angular speed (rad/s) or speed (m/s) between grid
    points k-1 and k+1; it is masked (False) where that stretch touches a gap.

    Args:
        trajectory: the poses.
        signal: angular speed (needs orientations) or speed.
        dt_s: the grid step, seconds.
        max_gap_ns: longest interval between poses that is not a gap, nanoseconds.

    Returns:
        (G,) values and (G,) mask.
    """
    sampler = PoseSampler.from_start(trajectory, max_gap_ns=max_gap_ns)
    g = int(np.floor(trajectory.duration_s / dt_s)) + 1
    t = np.arange(g, dtype=np.float64) * np.float64(dt_s)
    ok = sampler.valid(t)
    values = np.zeros(g)
    mask = np.zeros(g, dtype=bool)
    if g < 3:
        return values, mask
    if signal is MotionSignal.ANGULAR_SPEED:
        q = sampler.quat_at(t)
        step = rotvec_of(compose_quat(conjugate_quat(q[:-2]), q[2:]))
    else:
        p = sampler.positions_at(t)
        step = p[2:] - p[:-2]
    values[1:-1] = row_norms(step) / (2.0 * dt_s)
    # Both ends valid and no gap between them (the sampler's gap count is per interval).
    mask[1:-1] = sampler.valid(t[1:-1], margin_s=dt_s)
    mask &= ok
    return values, mask


@dataclass(frozen=True, slots=True, eq=False)
class CoarseSearch:
    """The correlation of the motions at every lag: the curve, the candidates, the signals."""

    lags_s: FloatArray
    scores: FloatArray
    candidates_s: FloatArray
    best: float
    grid_dt_s: float
    warnings: tuple[str, ...]
    signals: DriftSignals


def coarse_search(
    reference: Trajectory, estimate: Trajectory, signal: MotionSignal, *, max_gap_ns: int
) -> CoarseSearch:
    """Correlate the motion signals at every lag where the recordings overlap enough.

    Raises:
        InputError: too few poses between gaps, or too little motion.
        AssociationError: the recordings cannot overlap, or their motions match nowhere.
    """
    dt_s = grid_dt_s(reference, estimate)
    f, mf = motion_signal(reference, signal, dt_s=dt_s, max_gap_ns=max_gap_ns)
    g, mg = motion_signal(estimate, signal, dt_s=dt_s, max_gap_ns=max_gap_ns)
    _check_signal(reference, f, mf, signal)
    _check_signal(estimate, g, mg, signal)
    # Centre and normalise first: the moment sums below then stay well conditioned.
    f = np.where(mf, (f - f[mf].mean()) / f[mf].std(), 0.0)
    g = np.where(mg, (g - g[mg].mean()) / g[mg].std(), 0.0)
    mff, mgf = mf.astype(np.float64), mg.astype(np.float64)
    nf, ng = f.shape[0], g.shape[0]
    size = 1 << int(np.ceil(np.log2(nf + ng - 1)))

    def corr(a: FloatArray, b: FloatArray) -> FloatArray:
        # c[m] = sum_j a[j + m] b[j], m = -(ng - 1) .. nf - 1 (ordered ascending).
        full = np.fft.irfft(np.fft.rfft(a, size) * np.conj(np.fft.rfft(b, size)), size)
        out: FloatArray = np.concatenate((full[size - (ng - 1) :], full[:nf]))
        return out

    n = np.rint(corr(mff, mgf))
    s_f = corr(f, mgf)
    s_g = corr(mff, g)
    s_ff = corr(f * f, mgf)
    s_gg = corr(mff, g * g)
    s_fg = corr(f, g)
    min_overlap = max(MIN_SAMPLES, MIN_OVERLAP_SHARE * min(mf.sum(), mg.sum()))
    ok = n >= min_overlap
    with np.errstate(divide="ignore", invalid="ignore"):
        nn = np.where(ok, n, 1.0)
        var_f = s_ff - s_f**2 / nn
        var_g = s_gg - s_g**2 / nn
        score = (s_fg - s_f * s_g / nn) / np.sqrt(var_f * var_g)
    ok &= (var_f > 1e-9 * nn) & (var_g > 1e-9 * nn) & np.isfinite(score)
    score = np.where(ok, score, np.nan)
    m = np.arange(-(ng - 1), nf)
    base_s = (int(reference.stamps_ns[0]) - int(estimate.stamps_ns[0])) / NS_PER_S
    lags_s = base_s + m * dt_s
    if not ok.any():
        msg = (
            f"{estimate.name!r} and {reference.name!r} cannot overlap in time by half of the "
            "shorter recording at any time offset; check that both record the same run."
        )
        raise AssociationError(msg, option="time_offset_s")
    best_i = int(np.nanargmax(score))
    best = float(score[best_i])
    if best < MIN_CORRELATION:
        msg = (
            f"The motions of {estimate.name!r} and {reference.name!r} match at no time "
            f"offset (best correlation {best:.2f}); check that both record the same run, "
            "or give the time offset."
        )
        raise AssociationError(msg, option="time_offset_s")
    notes: list[str] = []
    if best < WEAK_CORRELATION:
        notes.append(
            f"The motions correlate weakly (best {best:.2f}), so the estimated time offset "
            "may be wrong; check it against the plot of the correlation curve."
        )
    kept = _peaks_near_best(np.where(ok, score, -np.inf), best_i, dt_s)
    sub = np.array([_parabolic(score, k) for k in kept])
    candidates = base_s + (m[np.array(kept)] + sub) * dt_s
    signals = DriftSignals(reference=f, reference_mask=mf, estimate=g, estimate_mask=mg, dt_s=dt_s)
    return CoarseSearch(lags_s, score, candidates, best, dt_s, tuple(notes), signals)


def _peaks_near_best(sc: FloatArray, best_i: int, dt_s: float) -> list[int]:
    """Indices of the local maxima that fit almost as well as the best, one per peak."""
    best = float(sc[best_i])
    peak = np.zeros(sc.shape, dtype=bool)
    peak[1:-1] = (sc[1:-1] >= sc[:-2]) & (sc[1:-1] >= sc[2:])
    peak[best_i] = True
    noise = AMBIGUITY_NOISE_SHARE * (1.0 - best) + 0.02
    near = (sc >= CANDIDATE_SHARE * best) & (best - sc <= noise)
    cand = np.flatnonzero(peak & near)
    cand = cand[np.argsort(-sc[cand])]
    kept: list[int] = []
    sep = max(MIN_CANDIDATE_SEPARATION_S / dt_s, 2.0)
    for c in cand:  # a loop over the few peaks near the best, not over samples
        if all(abs(c - k) >= sep for k in kept):
            kept.append(int(c))
    return kept


def _parabolic(score: FloatArray, k: int) -> float:
    """Sub-sample shift of a peak from a parabola through it and its neighbours."""
    if k == 0 or k == score.shape[0] - 1:
        return 0.0
    a, b, c = score[k - 1], score[k], score[k + 1]
    den = a - 2.0 * b + c
    if not (np.isfinite(den) and den < 0):
        return 0.0
    return float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))


def _check_signal(
    trajectory: Trajectory, values: FloatArray, mask: BoolArray, signal: MotionSignal
) -> None:
    if mask.sum() < MIN_SAMPLES:
        msg = (
            f"Trajectory {trajectory.name!r} has too few poses between its gaps to correlate "
            "its motion; record a longer stretch without tracking loss or give the time offset."
        )
        raise InputError(msg, option="time_offset_s")
    std = float(values[mask].std())
    floor, unit, what = (
        (_MIN_ANGULAR_STD_RAD_S, "deg/s", "angular speed")
        if signal is MotionSignal.ANGULAR_SPEED
        else (_MIN_SPEED_STD_M_S, "m/s", "speed")
    )
    if std < floor:
        shown = np.degrees(std) if signal is MotionSignal.ANGULAR_SPEED else std
        msg = (
            f"The {what} of {trajectory.name!r} is nearly constant (it varies by {shown:.3g} "
            f"{unit}), too little motion to find the time offset; record a run that starts, "
            "stops and turns, or give the time offset."
        )
        raise InputError(msg, option="time_offset_s")
