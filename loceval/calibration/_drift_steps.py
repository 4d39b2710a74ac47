"""The clock drift's line and steps (private to :mod:`loceval.calibration.drift`).

Stage 3: a weighted robust line (Huber IRLS) through the windows' offsets, with steps added
by binary segmentation while significant. Stage 4: each step's time, the change point of
least cost over the relative motions (or positions) around it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from loceval.calibration._drift_windows import RowMaker, huber, robust_rms
from loceval.calibration.common import NS_PER_S
from loceval.core.arrays import FloatArray, IntArray
from loceval.trajectory import Trajectory

STEP_Z = 6.0
"""A step is added to the model when its size exceeds this many sigma (a higher bar than
the rate's: binary segmentation tries every window boundary, and picks the best)."""
MAX_STEPS = 3
HUBER_K = 2.0
"""Windows beyond this many robust sigmas of the line weigh less (Huber)."""


# --- stage 3: the line and its steps ----------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class Line:
    """A robust weighted fit of ``o = o_0 + beta c + sum_k J_k [c >= b_k]``.

    ``coef`` = (o_0, beta, J_1, ...); ``cov`` its covariance (Student-scaled); ``scale`` the
    windows' scatter about it in their own sigmas; ``weights`` each window's Huber weight;
    ``breaks_s`` each step's boundary, seconds after the epoch (between two windows).
    """

    coef: FloatArray
    cov: FloatArray
    scale: float
    weights: FloatArray
    breaks_s: tuple[float, ...]

    def at(self, c: FloatArray, *, steps: tuple[int, ...] | None = None) -> FloatArray:
        """The fitted offset at ``c`` (seconds after the epoch); ``steps``: which count."""
        out: FloatArray = self.coef[0] + self.coef[1] * c
        for k, b in enumerate(self.breaks_s):
            if steps is None or k in steps:
                out = out + self.coef[2 + k] * (c >= b)
        return out


def _design(c: FloatArray, breaks_s: tuple[float, ...]) -> FloatArray:
    cols = [np.ones_like(c), c, *((c >= b).astype(np.float64) for b in breaks_s)]
    return np.stack(cols, axis=1)


def robust_line(
    c: FloatArray, o: FloatArray, sigma: FloatArray, breaks_s: tuple[float, ...]
) -> Line:
    """Huber IRLS of the line with ``breaks_s``; the covariance scaled by the scatter.

    Standardised residuals ``e = (o - X b) / sigma`` get Huber weights at HUBER_K robust
    scales (the MAD of ``e``). The covariance is ``s² (X^T W X)^-1`` with ``W`` the Huber
    weights over ``sigma²`` and ``s²`` Huber's scale estimate ``sum psi(u)² s_0² / (n - p)``
    over the mean ``psi'`` squared, times Student's factor for ``n - p`` degrees of freedom.
    """
    from scipy.special import stdtrit  # noqa: PLC0415  (scipy loads when a drift is fitted)

    x = _design(c, breaks_s)
    n, p = x.shape
    w = 1.0 / sigma**2
    scale0 = 1.0
    weights = np.ones(n)
    coef: FloatArray = np.zeros(p)
    for _ in range(20):
        xtw = x.T * (w * weights)
        coef_new = np.asarray(np.linalg.lstsq(xtw @ x, xtw @ o, rcond=None)[0], dtype=np.float64)
        e = (o - x @ coef_new) / sigma
        scale0 = max(1.4826 * float(np.median(np.abs(e))), 1e-12)
        weights = huber(e / scale0, HUBER_K)[0]
        if np.allclose(coef_new, coef, rtol=0, atol=1e-10):
            coef = coef_new
            break
        coef = coef_new
    e = (o - x @ coef) / sigma
    _, psi, dpsi = huber(e / scale0, HUBER_K)
    dof = max(n - p, 1)
    mean_dpsi = max(float(dpsi.mean()), 1e-3)
    scale2 = float((psi**2).sum()) * scale0**2 / dof / mean_dpsi**2
    info = (x.T * (w * weights)) @ x
    cov = scale2 * np.linalg.pinv(info)
    factor = float(stdtrit(dof, 0.99865)) / 3.0  # Student's t at 3 sigma, over 3
    return Line(
        coef=coef,
        cov=cov * factor**2,
        scale=math.sqrt(scale2),
        weights=weights,
        breaks_s=breaks_s,
    )


def fit_with_steps(c: FloatArray, o: FloatArray, sigma: FloatArray, *, window_s: float) -> Line:
    """The line, with steps added one at a time while the next is significant.

    Binary segmentation: every boundary between two windows (two windows at least on either
    side of it, and of any step already in) is tried with the current Huber weights held;
    the one of least weighted squares is refitted robustly and kept when its size exceeds
    :data:`STEP_Z` sigma.
    """
    order = np.argsort(c)
    c, o, sigma = c[order], o[order], sigma[order]
    line = robust_line(c, o, sigma, ())
    for _ in range(MAX_STEPS):
        candidates = [
            0.5 * (c[k - 1] + c[k])
            for k in range(2, c.shape[0] - 1)
            if all(abs(0.5 * (c[k - 1] + c[k]) - b) > 1.5 * window_s for b in line.breaks_s)
        ]
        if not candidates:
            break
        w = line.weights / sigma**2
        best, best_cost = None, np.inf
        for b in candidates:  # a loop over window boundaries, each fit vectorised
            x = _design(c, (*line.breaks_s, b))
            xtw = x.T * w
            coef = np.linalg.lstsq(xtw @ x, xtw @ o, rcond=None)[0]
            cost = float((w * (o - x @ coef) ** 2).sum())
            if cost < best_cost:
                best, best_cost = b, cost
        assert best is not None  # noqa: S101
        trial = robust_line(c, o, sigma, (*line.breaks_s, best))
        size, sd = trial.coef[-1], math.sqrt(trial.cov[-1, -1])
        if abs(size) <= STEP_Z * sd:
            break
        line = trial
    weights = np.empty_like(line.weights)
    weights[order] = line.weights
    return replace(line, weights=weights)


# --- stage 4: when each step happened ---------------------------------------------------------


def refine_step(
    maker: RowMaker,
    estimate: Trajectory,
    line: Line,
    k: int,
    *,
    window_s: float,
    ref_t0_ns: int,
) -> tuple[int, tuple[float, float]]:
    """Place step ``k`` at the change point of least cost among the estimate's stamps.

    Every row (relative motion, or position) within 1.5 windows of the step's boundary is
    judged with the offset before the step (cost ``c0``), after it (``c1``) and, for a
    relative motion whose ends lie on either side, before at its start and after at its
    end (``c01``); a change point at stamp ``s_q`` costs what each row costs then (the sum
    of its squared standardised residuals, capped at 5 sigma each), from cumulative sums.
    The profile-likelihood interval (cost within 1 of the least) gives the sigma, with the
    interval between the two poses either side of the change (uniform) added.

    Returns:
        The estimate's first stamp after the step, and (when, on the reference's clock in
        ns after its first pose; its 1-sigma in ns).
    """
    epoch = int(estimate.stamps_ns[0])
    boundary = line.breaks_s[k]
    others = tuple(m for m in range(len(line.breaks_s)) if m != k)
    lo_ns = epoch + round((boundary - 1.5 * window_s) * NS_PER_S)
    hi_ns = epoch + round((boundary + 1.5 * window_s) * NS_PER_S)
    stamps = estimate.stamps_ns
    part = estimate.select(np.flatnonzero((stamps >= lo_ns) & (stamps <= hi_ns)))
    rows = maker.make(part, len(part))

    def offsets(stamp: IntArray, *, after: bool) -> FloatArray:
        c = (stamp - np.int64(epoch)).astype(np.float64) / NS_PER_S
        out: FloatArray = line.at(c, steps=others) + (line.coef[2 + k] if after else 0.0)
        return out

    si, sj = rows.stamp_i, rows.stamp_j
    group = np.zeros(si.shape[0], dtype=np.intp)
    r0, ok0 = rows.residuals(offsets(si, after=False), offsets(sj, after=False), None, group, 1)
    r1, ok1 = rows.residuals(offsets(si, after=True), offsets(sj, after=True), None, group, 1)
    r01, ok01 = rows.residuals(offsets(si, after=False), offsets(sj, after=True), None, group, 1)
    ok = ok0 & ok1 & ok01
    scale = max(robust_rms(np.minimum(np.abs(r0), np.abs(r1))[ok]), 1e-12)

    def cost(r: FloatArray) -> FloatArray:
        out: FloatArray = np.where(ok, np.minimum((r / scale) ** 2, 25.0).sum(axis=1), 0.0)
        return out

    c0, c1, c01 = cost(r0), cost(r1), cost(r01)
    cand = part.stamps_ns[1:]  # the step takes effect from stamp q on (q >= 1)
    by_j, by_i = np.argsort(sj, kind="stable"), np.argsort(si, kind="stable")

    def cumulative(c: FloatArray, order: IntArray) -> FloatArray:
        return np.concatenate(([0.0], np.cumsum(c[order])))

    nj = np.searchsorted(sj[by_j], cand, side="left")  # rows whose end is before s_q
    ni = np.searchsorted(si[by_i], cand, side="left")  # rows whose start is before s_q
    c1_i, c01_i, c01_j = cumulative(c1, by_i), cumulative(c01, by_i), cumulative(c01, by_j)
    total = cumulative(c0, by_j)[nj] + (c1_i[-1] - c1_i[ni]) + (c01_i[ni] - c01_j[nj])
    q = int(np.argmin(total))
    near = cand[total - total[q] <= 1.0]
    before_ns, after_ns = int(part.stamps_ns[q]), int(cand[q])
    # Reference times (ns after the reference's first pose) of the poses either side.
    t_before = before_ns - ref_t0_ns + offsets(np.array([before_ns]), after=False)[0] * NS_PER_S
    t_after = after_ns - ref_t0_ns + offsets(np.array([after_ns]), after=True)[0] * NS_PER_S
    width_ns = float(max(int(near.max()) - after_ns, after_ns - int(near.min())))
    sigma_ns = math.hypot(width_ns, (t_after - t_before) / math.sqrt(12.0))
    return after_ns, (0.5 * (t_before + t_after), sigma_ns)
