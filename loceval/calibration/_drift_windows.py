"""The clock drift's windows (private to :mod:`loceval.calibration.drift`): their offsets.

Stage 1, coarse: per window, the masked Pearson correlation of the motion signals at every
lag near the prior (batched FFTs). Stage 2, fine: Gauss-Newton on every window's offset at
once over residual rows: relative rotations ``log((A X)^T X B)`` with the device rotation
``X`` (refined once the offsets follow a line), or positions with each window aligned by its
own Umeyama transform (batched), the alignment profiled out by differencing through it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from loceval.calibration.common import (
    NS_PER_S,
    PoseSampler,
    make_pairs,
    quat_matrices,
    rotate,
    rotvec_of,
)
from loceval.calibration.motion import DriftSignals, MotionSignal, grid_dt_s, motion_signal
from loceval.core.arrays import BoolArray, FloatArray, IntArray
from loceval.core.geometry import compose_quat, conjugate_quat
from loceval.trajectory import Trajectory

ComplexArray = NDArray[np.complex128]

MIN_WINDOW_CORRELATION = 0.3
"""A window whose motions correlate less at every lag has no coarse offset."""
MIN_WINDOW_PAIRS = 20
"""Fewest relative motions that give a window its offset."""
_FINE_ITERATIONS = 6
MAX_WINDOW_SIGMA_S = 0.1
"""A window whose offset is known worse than this (seconds) has none (no motion to tell)."""
WEAK_AXIS_SHARE = 1e-3
"""The device rotation is not refined along directions whose information is below this share
of the largest (as :data:`loceval.calibration.handeye.WEAK_EXCITATION`)."""
LEVER_ROUNDS = 40
_FD_STEP_S = 1e-3
_CONVERGED_S = 1e-5
"""Gauss-Newton stops when no window moves more (10 µs: a tenth of a good window's sigma)."""


def motion_signals(reference: Trajectory, estimate: Trajectory, *, max_gap_ns: int) -> DriftSignals:
    """The motion signals (angular speed, or speed position-only) of both sides."""
    use_rotation = reference.has_orientation and estimate.has_orientation
    signal = MotionSignal.ANGULAR_SPEED if use_rotation else MotionSignal.SPEED
    dt = grid_dt_s(reference, estimate)
    f, mf = motion_signal(reference, signal, dt_s=dt, max_gap_ns=max_gap_ns)
    g, mg = motion_signal(estimate, signal, dt_s=dt, max_gap_ns=max_gap_ns)
    return DriftSignals(f, mf, g, mg, dt)


def coarse_offsets(
    reference: Trajectory,
    estimate: Trajectory,
    prior_s: FloatArray,
    signals: DriftSignals,
    *,
    window_s: float,
    search_s: float,
) -> FloatArray:
    """Each window's offset from the motion signals' correlation (NaN where it is weak).

    The masked, overlap-normalised Pearson correlation of every window of the estimate's
    signal against the reference's, at every grid lag within ``search_s`` of the prior
    offsets ``prior_s`` (one per window, each ``window_s`` long from the estimate's start)
    (six correlations per window, all windows in one batch of FFTs), then a parabola
    through the best lag and its neighbours.
    """
    dt = signals.dt_s
    f, mf = signals.reference, signals.reference_mask
    g, mg = signals.estimate, signals.estimate_mask
    length = max(int(window_s / dt), 3)
    lags = int(np.ceil(search_s / dt))
    count = prior_s.shape[0]
    starts = np.floor(np.arange(count) * window_s / dt).astype(np.intp)
    shift = ((int(estimate.stamps_ns[0]) - int(reference.stamps_ns[0])) / NS_PER_S + prior_s) / dt
    base = np.rint(shift).astype(np.intp)
    # a: the estimate's windows (W, length); b: the reference around them (W, length + 2 lags).
    ia = starts[:, None] + np.arange(length)[None, :]
    ib = (starts + base - lags)[:, None] + np.arange(length + 2 * lags)[None, :]
    a, ma = _take(g, mg, ia)
    b, mb = _take(f, mf, ib)
    size = 1 << int(np.ceil(np.log2(2 * length + 2 * lags)))

    def spectrum(x: FloatArray) -> ComplexArray:
        out: ComplexArray = np.fft.rfft(x, size, axis=1)
        return out

    fa, fa2, fma = spectrum(a), spectrum(a * a), spectrum(ma)
    fb, fb2, fmb = spectrum(b), spectrum(b * b), spectrum(mb)
    span = 2 * lags + 1

    def corr(x: ComplexArray, y: ComplexArray) -> FloatArray:
        # sum_j a[j] b[j + n], n = 0 .. 2 lags: the lag n - lags about the prior.
        out: FloatArray = np.fft.irfft(y * np.conj(x), size, axis=1)[:, :span]
        return out

    n = np.rint(corr(fma, fmb))
    s_a, s_b = corr(fa, fmb), corr(fma, fb)
    s_aa, s_bb, s_ab = corr(fa2, fmb), corr(fma, fb2), corr(fa, fb)
    with np.errstate(divide="ignore", invalid="ignore"):
        nn = np.maximum(n, 1.0)
        var_a = s_aa - s_a**2 / nn
        var_b = s_bb - s_b**2 / nn
        score = (s_ab - s_a * s_b / nn) / np.sqrt(var_a * var_b)
    ok = (n >= 0.5 * length) & (var_a > 1e-9 * nn) & (var_b > 1e-9 * nn) & np.isfinite(score)
    score = np.where(ok, score, -np.inf)
    best = np.argmax(score, axis=1)
    rows = np.arange(count)
    peak = score[rows, best]
    # A parabola through the peak and its neighbours (where all three are finite).
    left = score[rows, np.clip(best - 1, 0, span - 1)]
    right = score[rows, np.clip(best + 1, 0, span - 1)]
    finite = np.isfinite(left) & np.isfinite(right) & np.isfinite(peak)
    left, right, mid = (np.where(finite, v, 0.0) for v in (left, right, peak))
    den = left - 2.0 * mid + right
    inner = finite & (best > 0) & (best < span - 1) & (den < 0)
    sub = np.where(inner, 0.5 * (left - right) / np.where(inner, den, -1.0), 0.0)
    sub = np.clip(sub, -0.5, 0.5)
    offsets = (int(reference.stamps_ns[0]) - int(estimate.stamps_ns[0])) / NS_PER_S + (
        base - lags + best + sub
    ) * dt
    out: FloatArray = np.where(peak >= MIN_WINDOW_CORRELATION, offsets, np.nan)
    return out


def _take(values: FloatArray, mask: BoolArray, index: IntArray) -> tuple[FloatArray, FloatArray]:
    """Values and mask (as floats) at ``index``, masked (0) outside the array."""
    inside = (index >= 0) & (index < values.shape[0])
    at = np.clip(index, 0, values.shape[0] - 1)
    m = inside & mask[at]
    return np.where(m, values[at], 0.0), m.astype(np.float64)


# --- stage 2: the windows' fine offsets -------------------------------------------------------


class Rows(Protocol):
    """Residual rows (relative motions, or positions) whose ends have stamps of the estimate."""

    stamp_i: IntArray
    stamp_j: IntArray

    def residuals(
        self, d_i: FloatArray, d_j: FloatArray, mask: BoolArray | None, group: IntArray, groups: int
    ) -> tuple[FloatArray, BoolArray]:
        """(n, c) residuals with offsets ``d_i``/``d_j`` at the ends, and which are valid."""
        ...


class RotationPairs:
    """One-second relative motions of the estimate, residuals ``log((A X)^T X B)`` at any offsets.

    ``A`` is the reference's motion between ``t_i + d_i`` and ``t_j + d_j``, ``B`` the
    estimate's between its stamps ``t_i`` and ``t_j``, ``X`` the device rotation. Pairs
    share no pose (:func:`loceval.calibration.common.make_pairs`), so their residuals are
    independent.
    """

    def __init__(
        self,
        sampler: PoseSampler,
        estimate: Trajectory,
        rotation: FloatArray,
        *,
        offset_ns: int,
        max_pairs: int,
    ) -> None:
        """Pair the estimate's poses and keep their motions."""
        from loceval.core.rotation import Rotation  # noqa: PLC0415

        assert estimate.quat_xyzw is not None  # noqa: S101  (the caller checks)
        # Pairs are chosen on tracked reference at the prior offset; the reference's
        # coverage is checked again at every evaluation, at the offsets then tried.
        pairs = make_pairs(
            estimate,
            sampler,
            offset_ns=offset_ns,
            window_s=1.0,
            margin_s=0.0,
            max_pairs=max_pairs,
        )
        self.sampler = sampler
        q = estimate.quat_xyzw
        self.b_q = compose_quat(conjugate_quat(q[pairs.i]), q[pairs.j])
        self.qx = np.broadcast_to(Rotation.from_matrix(rotation).as_quat(), self.b_q.shape)
        self.stamp_i = estimate.stamps_ns[pairs.i]
        self.stamp_j = estimate.stamps_ns[pairs.j]
        self.t_i = (self.stamp_i - sampler.origin_ns).astype(np.float64) / NS_PER_S
        self.t_j = (self.stamp_j - sampler.origin_ns).astype(np.float64) / NS_PER_S

    def residuals(
        self,
        d_i: FloatArray,
        d_j: FloatArray,
        _mask: BoolArray | None,
        _group: IntArray,
        _groups: int,
    ) -> tuple[FloatArray, BoolArray]:
        """(n, 3) rotation residuals (radians) and whether both ends lie on tracked reference."""
        a, ok = self._motions(d_i, d_j)
        return self._rotation_residuals(a, self.qx), ok

    def _motions(self, d_i: FloatArray, d_j: FloatArray) -> tuple[FloatArray, BoolArray]:
        """The reference's relative rotations ``A`` at the offsets, and their validity."""
        ti, tj = self.t_i + d_i, self.t_j + d_j
        ok = self.sampler.valid(ti) & self.sampler.valid(tj)
        a = compose_quat(conjugate_quat(self.sampler.quat_at(ti)), self.sampler.quat_at(tj))
        return a, ok

    def _rotation_residuals(self, a: FloatArray, qx: FloatArray) -> FloatArray:
        qx = np.broadcast_to(qx, a.shape)
        lhs = compose_quat(a, qx)
        return rotvec_of(compose_quat(conjugate_quat(lhs), compose_quat(qx, self.b_q)))

    def refine_rotation(self, d_i: FloatArray, d_j: FloatArray) -> None:
        """Refine the device rotation with the offsets ``d_i``/``d_j`` (Gauss-Newton, Huber).

        The drift's windows are as good as the device rotation: one off by a degree biases
        each window's offset by what its motion makes of it (milliseconds, varying along
        the run), so the rotation is fitted again once the offsets follow the line. About
        an axis that no motion excites (a ground robot's z) it stays as it was (the
        pseudo-inverse drops what the data do not tell, as
        :func:`loceval.calibration.common.weak_axes` judges them).
        """
        from loceval.core.rotation import Rotation  # noqa: PLC0415

        a, ok = self._motions(d_i, d_j)
        qx = self.qx[0]
        h = 1e-5
        nudges = Rotation.from_rotvec(np.eye(3) * h).as_quat()
        for _iteration in range(4):
            r = self._rotation_residuals(a, qx)
            jac = np.stack(
                [
                    (self._rotation_residuals(a, compose_quat(nudges[k], qx)) - r) / h
                    for k in range(3)
                ],
                axis=2,
            )
            scale = max(robust_rms(r[ok]), 1e-12)
            weight = huber(r / scale, 3.0)[0] * ok[:, None]
            normal = np.einsum("nci,nc,ncj->ij", jac, weight, jac)
            grad = np.einsum("nci,nc,nc->i", jac, weight, r)
            step = -np.linalg.pinv(normal, rcond=WEAK_AXIS_SHARE) @ grad
            qx = compose_quat(Rotation.from_rotvec(step).as_quat(), qx)
            if np.abs(step).max() < 1e-8:
                break
        self.qx = np.broadcast_to(qx, self.b_q.shape)

    @property
    def rotation(self) -> FloatArray:
        """(3, 3) the device rotation the residuals use."""
        from loceval.core.rotation import Rotation  # noqa: PLC0415

        out: FloatArray = Rotation.from_quat(self.qx[0]).as_matrix()
        return out


class PositionRows:
    """Estimate positions against the reference's, each group aligned by its own transform.

    ``residuals`` interpolates the reference at ``t + d_i`` (a position has one time, so
    ``d_j`` is unused), aligns each group's estimate positions onto it (Umeyama, batched
    over the groups, on the rows of ``mask`` when given) and returns the (n, 3) residuals in
    metres; a forward difference of them in the offset is then its Jacobian with the
    alignment profiled out (variable projection).
    """

    def __init__(
        self,
        sampler: PoseSampler,
        estimate: Trajectory,
        *,
        with_scale: bool,
        max_rows: int,
    ) -> None:
        """Keep every ``stride``-th position (at most ``max_rows``)."""
        stride = max(1, int(np.ceil(len(estimate) / max_rows)))
        self.sampler = sampler
        self.stamp_i = estimate.stamps_ns[::stride]
        self.stamp_j = self.stamp_i
        self.t = (self.stamp_i - sampler.origin_ns).astype(np.float64) / NS_PER_S
        self.p = estimate.positions_xyz[::stride]
        self.with_scale = with_scale
        self.held: tuple[FloatArray, FloatArray, FloatArray] | None = None
        self.lever = np.zeros(3)

    def _reference(self, t: FloatArray) -> FloatArray:
        """The reference's positions at ``t``, moved by the lever arm (in its body frame)."""
        q = self.sampler.positions_at(t)
        if not self.lever.any():
            return q
        out: FloatArray = q + rotate(self.sampler.quat_at(t), np.broadcast_to(self.lever, q.shape))
        return out

    def refine_lever(self, d: FloatArray, bounds_ns: IntArray) -> None:
        """Estimate the lever arm from the tracked body to the estimated point (metres).

        A position-only system measures a point (a tag, an antenna) some way from the
        tracked body; as the body turns, that point swings about it, a motion no rigid
        alignment takes up and which, as it goes with the velocity, would bias every
        window's offset alike. With the reference's orientations it is one vector in the
        body's frame: least squares of ``R_ref L = s R_w p_est + t_w - p_ref`` over all
        rows, alternating with the windows' alignments (which take up part of the swing, so
        that each round gets about half of what is left) until it moves by under a micrometre.
        """
        if self.sampler.quat is None:
            return
        group = np.searchsorted(bounds_ns, self.stamp_i, side="right")
        groups = bounds_ns.shape[0] + 1
        t = self.t + d
        ok = self.sampler.valid(t)
        body = self.sampler.positions_at(t)
        rot_ref = quat_matrices(self.sampler.quat_at(t))
        for _round in range(LEVER_ROUNDS):
            before = self.lever
            q = self._reference(t)
            rot, scale, trans = _umeyama_groups(
                self.p, q, group, ok, groups=groups, with_scale=self.with_scale
            )
            aligned = scale[group, None] * np.einsum("nij,nj->ni", rot[group], self.p)
            gap = aligned + trans[group] - body
            # R^T R = I: the normal equations' solution is the mean of R^T gap.
            self.lever = np.einsum("nji,nj->i", rot_ref[ok], gap[ok]) / max(int(ok.sum()), 1)
            if np.abs(self.lever - before).max() < 1e-6:
                break

    def hold_alignment(self, d: FloatArray, use: BoolArray) -> None:
        """Align the rows ``use`` once, at offsets ``d``, and keep that for what follows.

        Judging one row under two offsets (a step's sides) must not align anew each time:
        the alignment would take up part of the difference it is to tell.
        """
        t = self.t + d
        group = np.zeros(t.shape[0], dtype=np.intp)
        q = self._reference(t)
        ok = self.sampler.valid(t) & use
        self.held = _umeyama_groups(self.p, q, group, ok, groups=1, with_scale=self.with_scale)

    def residuals(
        self,
        d_i: FloatArray,
        _d_j: FloatArray,
        mask: BoolArray | None,
        group: IntArray,
        groups: int,
    ) -> tuple[FloatArray, BoolArray]:
        """(n, 3) residuals after each group's alignment, and the rows on tracked reference."""
        t = self.t + d_i
        ok = self.sampler.valid(t)
        q = self._reference(t)
        use = ok if mask is None else mask & ok
        if self.held is not None:
            rot, scale, trans = self.held
            aligned = scale[group, None] * np.einsum("nij,nj->ni", rot[group], self.p)
            return q - aligned - trans[group], ok
        rot, scale, trans = _umeyama_groups(
            self.p, q, group, use, groups=groups, with_scale=self.with_scale
        )
        aligned = scale[group, None] * np.einsum("nij,nj->ni", rot[group], self.p) + trans[group]
        return _detrended(q - aligned, self.t, group, use, groups=groups), ok


def _detrended(
    r: FloatArray, t: FloatArray, group: IntArray, use: BoolArray, *, groups: int
) -> FloatArray:
    """Residuals less each group's straight line in time (its drift velocity), least squares.

    An estimate drifts (SLAM): within a window its positions move away from the reference
    at a nearly constant velocity, which a rigid alignment cannot take up and which the
    offset's Jacobian (the reference's velocity) would otherwise partly explain; shared by
    every window, it would bias all their offsets alike.
    """
    w = use.astype(np.float64)
    n = np.maximum(np.bincount(group, w, minlength=groups), 1.0)
    dt = t - np.bincount(group, w * t, minlength=groups)[group] / n[group]
    var = np.maximum(np.bincount(group, w * dt * dt, minlength=groups), 1e-300)
    cols = [np.bincount(group, w * dt * r[:, k], minlength=groups) / var for k in range(3)]
    slope = np.stack(cols, axis=1)
    mean = np.stack(
        [np.bincount(group, w * r[:, k], minlength=groups) / n for k in range(3)], axis=1
    )
    out: FloatArray = r - mean[group] - slope[group] * dt[:, None]
    return out


def _umeyama_groups(
    p: FloatArray,
    q: FloatArray,
    group: IntArray,
    use: BoolArray,
    *,
    groups: int,
    with_scale: bool,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Umeyama's ``q ≈ s R p + t`` per group (1991, eq. 34-42), batched.

    Returns:
        (G, 3, 3) rotations, (G,) scales (1 without ``with_scale``), (G, 3) translations.
    """
    w = use.astype(np.float64)
    n = np.maximum(np.bincount(group, w, minlength=groups), 1.0)

    def mean(x: FloatArray) -> FloatArray:
        cols = [np.bincount(group, w * x[:, k], minlength=groups) for k in range(x.shape[1])]
        out: FloatArray = np.stack(cols, axis=1) / n[:, None]
        return out

    mp, mq = mean(p), mean(q)
    pc, qc = p - mp[group], q - mq[group]
    cross = mean((qc[:, :, None] * pc[:, None, :]).reshape(-1, 9)).reshape(groups, 3, 3)
    u, d, vt = np.linalg.svd(cross)
    sign = np.ones((groups, 3))
    sign[:, 2] = np.where(np.linalg.det(u @ vt) < 0, -1.0, 1.0)
    rot = (u * sign[:, None, :]) @ vt
    scale = np.ones(groups)
    if with_scale:
        var_p = mean((pc * pc).sum(axis=1, keepdims=True))[:, 0]
        scale = (d * sign).sum(axis=1) / np.maximum(var_p, 1e-300)
    trans = mq - scale[:, None] * np.einsum("gij,gj->gi", rot, mp)
    return rot, scale, trans


class RowMaker:
    """Makes the residual rows of a trajectory: relative rotations, or positions."""

    def __init__(
        self,
        sampler: PoseSampler,
        rotation: FloatArray | None,
        *,
        offset_ns: int,
        with_scale: bool,
    ) -> None:
        """Keep what the rows need (``offset_ns``: where relative motions are chosen)."""
        self.sampler = sampler
        self.rotation = rotation
        self.offset_ns = offset_ns
        self.with_scale = with_scale
        self.lever = np.zeros(3)

    def make(self, trajectory: Trajectory, max_rows: int) -> Rows:
        """The rows of ``trajectory`` (at most ``max_rows``, thinned evenly)."""
        if self.rotation is not None:
            return RotationPairs(
                self.sampler,
                trajectory,
                self.rotation,
                offset_ns=self.offset_ns,
                max_pairs=max_rows,
            )
        rows = PositionRows(self.sampler, trajectory, with_scale=self.with_scale, max_rows=max_rows)
        rows.lever = self.lever
        return rows


@dataclass(frozen=True, slots=True, eq=False)
class Fine:
    """The windows' offsets after Gauss-Newton (NaN: no offset).

    ``centre_s``: where along the estimate's clock (seconds after its first stamp) each
    window's offset holds; ``rows``: how many valid rows gave it.
    """

    offset_s: FloatArray
    sigma_s: FloatArray
    centre_s: FloatArray
    rows: FloatArray

    @property
    def has_offset(self) -> BoolArray:
        """Which windows have an offset."""
        out: BoolArray = np.isfinite(self.offset_s) & np.isfinite(self.sigma_s)
        return out


def huber(z: FloatArray, k: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Huber's weight, influence and its derivative at standardised residuals ``z``."""
    a = np.abs(z)
    inside = a <= k
    weight = np.where(inside, 1.0, k / np.maximum(a, 1e-300))
    psi = np.where(inside, z, k * np.sign(z))
    return weight, psi, inside.astype(np.float64)


def robust_rms(r: FloatArray) -> float:
    """RMS of residuals from their median absolute value (outliers do not inflate it)."""
    if r.size == 0:
        return 1.0
    return float(1.4826 * np.median(np.abs(r)))


def fine_offsets(
    rows: Rows,
    bounds_ns: IntArray,
    epoch_ns: int,
    start: FloatArray,
    *,
    slope: float | None = None,
    centre_s: FloatArray | None = None,
) -> Fine:
    """Gauss-Newton on every window's offset, all windows at once.

    The windows are cut at ``bounds_ns`` (the estimate's clock, increasing); a row belongs
    to the window of its first end, and each end takes the offset of its own window (a
    relative motion across a step takes the offset before at its start and after at its
    end). With ``slope``, the offset within a window follows it about ``centre_s``, where
    the window's offset then holds; without, it is constant, and holds at the window's
    centre of information (the rows' times weighted by their information).

    The step of each window is ``-sum(w J r) / sum(w J²)`` over its rows, ``J`` the forward
    difference of the residuals in a common shift of the offsets, ``w`` Huber's weights at
    3 robust sigmas of the residuals (their scale from the first iteration, then held); the
    1-sigma of each is its sandwich ``sqrt(sum (J psi)²) / sum(J² psi')``.
    """
    count = bounds_ns.shape[0] + 1
    w_i = np.searchsorted(bounds_ns, rows.stamp_i, side="right")
    w_j = np.searchsorted(bounds_ns, rows.stamp_j, side="right")
    since_i = (rows.stamp_i - np.int64(epoch_ns)).astype(np.float64) / NS_PER_S
    since_j = (rows.stamp_j - np.int64(epoch_ns)).astype(np.float64) / NS_PER_S
    trend_i = trend_j = np.zeros(since_i.shape)
    if slope is not None and centre_s is not None:
        trend_i = slope * (since_i - centre_s[w_i])
        trend_j = slope * (since_j - centre_s[w_j])

    def residuals(d: FloatArray, mask: BoolArray | None) -> tuple[FloatArray, BoolArray]:
        return rows.residuals(d[w_i] + trend_i, d[w_j] + trend_j, mask, w_i, count)

    live = np.isfinite(start)
    d = np.where(live, start, 0.0)

    def evaluate(d: FloatArray) -> tuple[FloatArray, FloatArray, BoolArray]:
        r, ok = residuals(d, None)
        r_h, ok_h = residuals(d + _FD_STEP_S, ok)
        return r, (r_h - r) / _FD_STEP_S, ok & ok_h & live[w_i]

    r, jac, ok = evaluate(d)
    scale = max(robust_rms(r[ok]), 1e-12)  # held from here: the cost stays one function
    for _iteration in range(_FINE_ITERATIONS):
        weight = huber(r / scale, 3.0)[0] * ok[:, None]
        num = np.bincount(w_i, (weight * jac * r).sum(axis=1), minlength=count)
        den = np.bincount(w_i, (weight * jac * jac).sum(axis=1), minlength=count)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.clip(np.where(den > 0, -num / den, 0.0), -0.1, 0.1)
        d = d + step
        r, jac, ok = evaluate(d)
        if (np.abs(step) < _CONVERGED_S).all():
            break
    _, psi, dpsi = huber(r / scale, 3.0)
    okf = ok[:, None].astype(np.float64)
    g = jac / scale
    score = (okf * g * psi).sum(axis=1)
    info = (okf * g * g * dpsi).sum(axis=1)
    meat = np.bincount(w_i, score * score, minlength=count)
    bread = np.bincount(w_i, info, minlength=count)
    used = np.bincount(w_i, ok.astype(np.float64), minlength=count)
    mid = 0.5 * (since_i + since_j)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.sqrt(meat) / bread
        centre = np.bincount(w_i, info * mid, minlength=count) / bread
    if slope is not None and centre_s is not None:
        centre = centre_s
    good = live & (used >= MIN_WINDOW_PAIRS) & (bread > 0) & np.isfinite(sigma) & (sigma > 0)
    good &= sigma < MAX_WINDOW_SIGMA_S
    return Fine(
        offset_s=np.where(good, d, np.nan),
        sigma_s=np.where(good, sigma, np.nan),
        centre_s=np.where(good, centre, np.nan),
        rows=used.astype(np.float64),
    )
