"""The clock drift's line and steps (private to :mod:`loceval.calibration.drift`).

Stage 3: a weighted robust line (Huber IRLS) through the windows' offsets, with steps added
by binary segmentation while significant. Stage 4: each step's time, the change point of
least cost over the relative motions (or positions) around it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from loceval.calibration._drift_windows import PositionRows, RowMaker, huber, robust_rms
from loceval.calibration.common import NS_PER_S
from loceval.core.arrays import FloatArray, IntArray
from loceval.trajectory import Trajectory

STEP_Z = 6.0
"""A step is added to the model when its size exceeds this many sigma (a higher bar than
the rate's: binary segmentation tries every window boundary, and picks the best)."""
STEP_WINDOW_Z = 4.0
"""... and one window's own scatter this many times: a step shows in the windows either side
of it, while a slow wander of the offsets (the estimate's heading drift seen through the
windows' motions) that a step would fit is small against it."""
MAX_STEPS = 3
LINE_SIGMA_SAFETY = 1.25
"""Factor on the line's sigmas (rate, offset, steps' sizes). Measured on the tuning recordings
(tests/clock_factory.py, 10 min, 20 to 40 seeds per family): the rate's and the offset's
errors had an RMS of 0.73 to 0.96 of the line's sigma on handheld, looping and position-only
runs, but 1.15 to 1.28 on ground robots, whose windows share a slow error (their offsets'
slope scatters more than the same windows' in shuffled order); an interval that misses is
worse than one a quarter wider."""
BOOTSTRAP_DRAWS = 400
"""Cost curves drawn for the sigma of a step's time."""
BOOTSTRAP_SEED = 42
CORRELATION_LAGS = 4
"""Window lags whose residual correlation widens the covariance (Bartlett weights)."""
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
    over the mean ``psi'`` squared, times Student's factor for ``n - p`` degrees of freedom,
    times the long-run variance factor of the residuals' correlation along the run
    ``1 + 2 sum_l (1 - l / (L + 1)) rho_l`` (Bartlett, ``L`` = CORRELATION_LAGS; never
    below 1): neighbouring windows share slow errors (heading drift), which independent
    windows would not; and times the measured LINE_SIGMA_SAFETY.
    """
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
    # The sandwich of the same fit, heteroscedasticity-consistent (HC1): where the
    # windows' own sigmas misjudge each other (a window with few telling motions), it
    # says more than the scale; each parameter takes the larger of the two variances.
    inv = np.linalg.pinv(info)
    u = w * weights * (o - x @ coef)
    hc = inv @ ((x.T * u**2) @ x) @ inv * n / dof
    widen = np.sqrt(np.maximum(np.diag(hc) / np.maximum(np.diag(cov), 1e-300), 1.0))
    cov = cov * np.outer(widen, widen)
    factor = _student_at_3_sigma(dof) / 3.0
    return Line(
        coef=coef,
        cov=cov * (factor * LINE_SIGMA_SAFETY) ** 2 * _long_run_factor(psi),
        scale=math.sqrt(scale2),
        weights=weights,
        breaks_s=breaks_s,
    )


def _student_at_3_sigma(dof: int) -> float:
    """Student's t quantile of the normal's 3 sigma (0.99865) for ``dof`` degrees of freedom.

    The Cornish-Fisher expansion of the t quantile about the normal one (Hill 1970, four
    terms): within 0.3 % of the exact value from 5 degrees of freedom on, 2 % low at 3; no
    scipy import for it.
    """
    z, v = 3.0, float(max(dof, 1))
    return (
        z
        + (z**3 + z) / (4 * v)
        + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * v**2)
        + (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / (384 * v**3)
        + (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / (92160 * v**4)
    )


def _long_run_factor(u: FloatArray) -> float:
    """``1 + 2 sum_l (1 - l / (L + 1)) rho_l`` of residuals in time order, at least 1."""
    total = float(u @ u)
    if total <= 0 or u.shape[0] <= CORRELATION_LAGS + 2:
        return 1.0
    lags = range(1, CORRELATION_LAGS + 1)
    rho = [float(u[lag:] @ u[:-lag]) / total for lag in lags]
    bartlett = sum(
        (1.0 - lag / (CORRELATION_LAGS + 1)) * r for lag, r in zip(lags, rho, strict=True)
    )
    return max(1.0, 1.0 + 2.0 * bartlett)


def fit_with_steps(c: FloatArray, o: FloatArray, sigma: FloatArray, *, window_s: float) -> Line:
    """The line, with steps added one at a time while the next is significant.

    Binary segmentation: every boundary between two windows (two windows at least on either
    side of it, and of any step already in) is tried with the current Huber weights held;
    the one of least weighted squares is refitted robustly and kept when its size exceeds
    :data:`STEP_Z` sigma and :data:`STEP_WINDOW_Z` times one window's scatter.
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
        window_sd = trial.scale * float(np.median(sigma))
        if abs(size) <= max(STEP_Z * sd, STEP_WINDOW_Z * window_sd):
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
    brk = epoch + round(boundary * NS_PER_S)
    if isinstance(rows, PositionRows):
        # Aligned on the rows whose side is not in question (a quarter window away).
        clear = np.abs(si - brk) > 0.25 * window_s * NS_PER_S
        shift = np.where(si >= brk, line.coef[2 + k], 0.0)
        rows.hold_alignment(offsets(si, after=False) + shift, clear)
    r0, ok0 = rows.residuals(offsets(si, after=False), offsets(sj, after=False), None, group, 1)
    r1, ok1 = rows.residuals(offsets(si, after=True), offsets(sj, after=True), None, group, 1)
    r01, ok01 = rows.residuals(offsets(si, after=False), offsets(sj, after=True), None, group, 1)
    ok = (ok0 & ok1 & ok01)[:, None]
    # The residuals' scale under the line as fitted: each row with the offsets of its side
    # of the windows' boundary (the smaller of two residuals would understate it).
    fitted = np.choose(np.where(sj < brk, 0, np.where(si >= brk, 1, 2))[:, None], (r0, r1, r01))
    scale = max(robust_rms(fitted[ok[:, 0]]), 1e-12)
    z0, z1, z01 = (np.where(ok, r / scale, 0.0) for r in (r0, r1, r01))
    cand = part.stamps_ns[1:]  # the step takes effect from stamp q on (q >= 1)
    curve = _ChangeCost(si, sj, cand)
    total = curve.total((z0**2).sum(axis=1), (z1**2).sum(axis=1), (z01**2).sum(axis=1))
    q = int(np.argmin(total))
    # When each candidate says the jump happened (ns after the reference's first pose): the
    # middle of the reference times of the poses either side, each on its side's clock.
    prev = part.stamps_ns[:-1]
    t_before = (prev - ref_t0_ns).astype(np.float64) + offsets(prev, after=False) * NS_PER_S
    t_after = (cand - ref_t0_ns).astype(np.float64) + offsets(cand, after=True) * NS_PER_S
    at_ns = 0.5 * (t_before + t_after)
    spread_ns = _change_spread(curve, (z0, z1, z01), q, at_ns)
    sigma_ns = math.hypot(spread_ns, (t_after[q] - t_before[q]) / math.sqrt(12.0))
    return int(cand[q]), (float(at_ns[q]), sigma_ns)


class _ChangeCost:
    """The cost of every change point from per-row costs, by cumulative sums.

    A row ``(s_i, s_j)`` costs ``c0`` when the change is after its end (``s_j < s_q``),
    ``c1`` when it is at or before its start (``s_i >= s_q``), and ``c01`` in between.
    """

    def __init__(self, si: IntArray, sj: IntArray, cand: IntArray) -> None:
        """Sort the rows by start and by end, and find each candidate's place."""
        self.si, self.sj, self.cand = si, sj, cand
        self.by_i = np.argsort(si, kind="stable")
        self.by_j = np.argsort(sj, kind="stable")
        self.ni = np.searchsorted(si[self.by_i], cand, side="left")  # rows starting before
        self.nj = np.searchsorted(sj[self.by_j], cand, side="left")  # rows ending before

    def total(self, c0: FloatArray, c1: FloatArray, c01: FloatArray) -> FloatArray:
        """(..., Q) the cost of each candidate; the costs are (..., n) per row."""

        def cumulative(c: FloatArray, order: IntArray) -> FloatArray:
            zero = np.zeros((*c.shape[:-1], 1))
            return np.concatenate((zero, np.cumsum(c[..., order], axis=-1)), axis=-1)

        c1_i, c01_i, c01_j = (
            cumulative(c1, self.by_i),
            cumulative(c01, self.by_i),
            cumulative(c01, self.by_j),
        )
        out: FloatArray = (
            cumulative(c0, self.by_j)[..., self.nj]
            + (c1_i[..., -1:] - c1_i[..., self.ni])
            + (c01_i[..., self.ni] - c01_j[..., self.nj])
        )
        return out


def _change_spread(
    curve: _ChangeCost,
    z: tuple[FloatArray, FloatArray, FloatArray],
    q: int,
    at_ns: FloatArray,
) -> float:
    """The RMS distance (ns) of the jump's time from ``at_ns[q]``, by parametric bootstrap.

    The change point's cost curve is a random walk about the true one, whose argmin
    scatters several times wider than the profile's ``cost - least <= 1`` interval when one
    row tells little (Hinkley 1970); so the curve is drawn again :data:`BOOTSTRAP_DRAWS`
    times with the change at ``q``: each row's standardised residuals in the state that
    change gives it are Gaussian noise ``e``, so in another state they are ``e + d`` (``d``
    the difference of the two states' residuals, in which the noise cancels), and the row
    costs ``|e + d|²`` there. The drawn argmins' times (``at_ns``: a change placed a pose
    late also puts that pose on the wrong clock) scatter about ``at_ns[q]`` by the sigma.
    """
    from scipy.signal import lfilter  # noqa: PLC0415  (scipy loads when a step is found)

    sq = curve.cand[q]
    state = np.where(curve.sj < sq, 0, np.where(curve.si >= sq, 1, 2))
    z_hat = np.choose(state[:, None], z)
    # The rows' residuals follow one another (positions share the estimate's slow drift):
    # the noise is drawn with their lag-one correlation (an AR(1) process along the rows).
    order = np.argsort(curve.si, kind="stable")
    seq = z_hat[order]
    rho = float(np.clip((seq[1:] * seq[:-1]).sum() / max((seq * seq).sum(), 1e-300), 0.0, 0.99))
    rng = np.random.default_rng(BOOTSTRAP_SEED)  # a fixed seed: the same data, the same sigma
    white = rng.standard_normal((BOOTSTRAP_DRAWS, *z_hat.shape))
    noise = np.empty_like(white)
    noise[:, order] = lfilter([math.sqrt(1.0 - rho**2)], [1.0, -rho], white, axis=1)
    costs = [((noise + (zs - z_hat)) ** 2).sum(axis=-1) for zs in z]
    drawn = np.argmin(curve.total(*costs), axis=-1)
    moved = np.abs(at_ns[drawn] - at_ns[q])
    # The drawn distances are discrete and long-tailed (most draws find the same pose, a
    # few one or two poses off, which also puts them on the other clock): the sigma is the
    # one whose 3 sigma holds 99.73 % of them, or their RMS if that is larger.
    return float(max(np.sqrt(np.mean(moved**2)), np.quantile(moved, 0.9973) / 3.0))
