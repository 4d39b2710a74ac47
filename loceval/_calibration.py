"""Shared machinery of the clock and device-offset estimation (private).

- :class:`PoseSampler`: the reference interpolated at float times (seconds after its first
  pose), linear positions and SLERP orientations, with a mask that never bridges a gap.
- :func:`hac_covariance`: the sandwich covariance of a least-squares fit whose residuals are
  correlated in time (Newey and West 1987, Bartlett weights), so that sigmas stay honest when
  neighbouring residuals share poses, interpolation and slow drift.
- :func:`fit_relative_motions`: the robust nonlinear least squares over relative motions
  ``A X = X B`` of short windows, jointly with the time offset (see :mod:`loceval.handeye`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from loceval._typing import BoolArray, FloatArray, IntArray
from loceval.geometry import compose_quat, conjugate_quat
from loceval.trajectory import Trajectory

NS_PER_S = 1_000_000_000
MAX_ITERATIONS = 30
RESCALE_ITERATIONS = 2
HUBER_K = 3.0
"""Residuals beyond this many robust sigmas get a linearly growing (Huber) cost."""


class PoseSampler:
    """A trajectory interpolated at float times, never across a gap.

    Times are float seconds after ``origin_ns`` (float64 keeps them to a fraction of a
    nanosecond over days), so a least-squares solver can move them by microseconds.
    """

    def __init__(self, trajectory: Trajectory, *, origin_ns: int, max_gap_ns: int) -> None:
        """Keep the arrays and the cumulative count of gaps."""
        self.trajectory = trajectory
        self.origin_ns = int(origin_ns)
        self.times_s = (trajectory.stamps_ns - self.origin_ns).astype(np.float64) / NS_PER_S
        self.positions = trajectory.positions_xyz
        self.quat = trajectory.quat_xyzw
        dt_ns = np.diff(trajectory.stamps_ns)
        # gaps_before[i]: how many gaps lie between pose 0 and pose i.
        self._gaps_before = np.concatenate(([0], np.cumsum(dt_ns > max_gap_ns)))

    def valid(self, times_s: FloatArray, *, margin_s: float = 0.0) -> BoolArray:
        """Whether every time within ``margin_s`` of each of ``times_s`` is bridged."""
        t = self.times_s
        n = t.shape[0]
        lo = np.searchsorted(t, times_s - margin_s, side="right") - 1
        hi = np.searchsorted(t, times_s + margin_s, side="left")
        inside = (lo >= 0) & (hi <= n - 1)
        lo_c = np.clip(lo, 0, n - 1)
        hi_c = np.clip(hi, 0, n - 1)
        out: BoolArray = inside & (self._gaps_before[hi_c] == self._gaps_before[lo_c])
        return out

    def positions_at(self, times_s: FloatArray) -> FloatArray:
        """Return (N, 3) positions at ``times_s`` (clamped at the ends; check :meth:`valid`)."""
        i, w = self._bracket(times_s)
        p = self.positions
        out: FloatArray = p[i] + w[:, None] * (p[i + 1] - p[i])
        return out

    def quat_at(self, times_s: FloatArray) -> FloatArray:
        """Return (N, 4) orientations x y z w at ``times_s`` (SLERP; needs orientations)."""
        assert self.quat is not None  # noqa: S101  (callers check has_orientation)
        i, w = self._bracket(times_s)
        return slerp(self.quat[i], self.quat[i + 1], w)

    def _bracket(self, times_s: FloatArray) -> tuple[IntArray, FloatArray]:
        t = self.times_s
        i = np.clip(np.searchsorted(t, times_s, side="right") - 1, 0, t.shape[0] - 2)
        w = np.clip((times_s - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0)
        return i, w


def hac_covariance(
    jac: FloatArray, residuals: FloatArray, groups: int, *, lag: int
) -> tuple[FloatArray, float]:
    """Sandwich covariance of least-squares parameters with time-correlated residuals.

    Rows come in ``groups`` consecutive blocks of equal size (one block per time step); the
    score of each block is ``J_b^T r_b``, and their autocovariance up to ``lag`` blocks is
    summed with Bartlett weights (Newey-West), so ``cov = B^-1 M B^-1`` with ``B = J^T J``.

    Args:
        jac: (R, P) Jacobian of the (weighted) residuals.
        residuals: (R,) weighted residuals at the solution.
        groups: number of blocks (R must be a multiple).
        lag: largest block lag whose correlation is counted.

    Returns:
        The (P, P) covariance and the ratio of the sandwich variance to the naive one
        (averaged over parameters; how much the correlation inflated it).
    """
    p = jac.shape[1]
    scores = (jac * residuals[:, None]).reshape(groups, -1, p).sum(axis=1)
    meat = scores.T @ scores
    for k in range(1, min(lag, groups - 1) + 1):  # a loop over lags, not over poses
        c = scores[:-k].T @ scores[k:]
        meat += (1.0 - k / (lag + 1.0)) * (c + c.T)
    bread = np.linalg.pinv(jac.T @ jac)
    cov: FloatArray = bread @ meat @ bread
    dof = max(residuals.shape[0] - p, 1)
    naive = bread * float(residuals @ residuals) / dof
    ratio = float(np.mean(np.diag(cov) / np.maximum(np.diag(naive), 1e-300)))
    return cov, ratio


def rotvec_of(quat_xyzw: FloatArray) -> FloatArray:
    """Return (N, 3) rotation vectors (radians) of (N, 4) unit quaternions.

    numpy instead of scipy's ``as_rotvec``, which costs about 1 µs per rotation in scipy
    1.17 (measured: 8 ms for 7,000) and ran dozens of times per least-squares solve.
    """
    q = np.asarray(quat_xyzw, dtype=np.float64)
    q = np.where(q[:, 3:4] < 0.0, -q, q)  # the shorter arc: w >= 0
    v = q[:, :3]
    s = np.linalg.norm(v, axis=1)
    w = q[:, 3]
    angle = 2.0 * np.arctan2(s, w)
    # angle / s -> 2 / w as s -> 0 (series of 2 atan(s/w) / s).
    small = s < 1e-8
    factor = np.where(small, 2.0 / np.where(small, w, 1.0), angle / np.where(small, 1.0, s))
    out: FloatArray = v * factor[:, None]
    return out


def quat_of(rotvec: FloatArray) -> FloatArray:
    """Return (N, 4) unit quaternions x y z w of (N, 3) rotation vectors (radians)."""
    r = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(r, axis=1)
    half = 0.5 * angle
    small = angle < 1e-8
    # sin(θ/2) / θ -> 1/2 - θ²/48 as θ -> 0.
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    out: FloatArray = np.column_stack((r * k[:, None], np.cos(half)))
    return out


def rotate(quat_xyzw: FloatArray, vectors: FloatArray) -> FloatArray:
    """Rotate matching rows: (N, 3) vectors by (N, 4) unit quaternions (numpy, no scipy)."""
    u = quat_xyzw[..., :3]
    w = quat_xyzw[..., 3:4]
    c = 2.0 * np.cross(u, vectors)
    out: FloatArray = vectors + w * c + np.cross(u, c)
    return out


def slerp(q0_xyzw: FloatArray, q1_xyzw: FloatArray, weights: FloatArray) -> FloatArray:
    """SLERP between matching rows (as :func:`loceval.geometry.slerp_pairs`, in numpy)."""
    delta = rotvec_of(compose_quat(conjugate_quat(q0_xyzw), q1_xyzw))
    return compose_quat(q0_xyzw, quat_of(delta * weights[:, None]))


def relative_motions(
    positions: FloatArray, quat_xyzw: FloatArray, i: IntArray, j: IntArray
) -> tuple[FloatArray, FloatArray]:
    """Return the motions ``T_i^-1 T_j``: (N, 4) rotations and (N, 3) translations."""
    q_inv = conjugate_quat(quat_xyzw[i])
    q_rel = compose_quat(q_inv, quat_xyzw[j])
    t_rel = rotate(q_inv, positions[j] - positions[i])
    return q_rel, t_rel


def solve_rotation(alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """Closed-form ``R`` with ``alpha_k ≈ R beta_k`` (Park and Martin 1994, eq. 16 via SVD).

    Args:
        alpha: (N, 3) rotation vectors of the reference's relative motions.
        beta: (N, 3) rotation vectors of the estimate's relative motions.

    Returns:
        (3, 3) rotation matrix (the Kabsch solution, reflection guarded).
    """
    H = beta.T @ alpha
    U, _, Vt = np.linalg.svd(H)
    S = np.eye(3)
    if np.linalg.det(Vt.T @ U.T) < 0:
        S[2, 2] = -1.0
    out: FloatArray = Vt.T @ S @ U.T
    return out


@dataclass(frozen=True, slots=True)
class RelativeFit:
    """The solution of :func:`fit_relative_motions`.

    ``cov`` is over ``[offset_s, rx, ry, rz, tx, ty, tz, log_scale]`` (rotation as a left
    perturbation about the reference body's axes, radians); rows and columns of fixed
    parameters are NaN.
    """

    offset_s: float
    rotation: FloatArray
    translation_m: FloatArray
    scale: float
    cov: FloatArray
    pairs: int
    rms_rotation_rad: float
    rms_translation_m: float
    correlation_inflation: float


@dataclass(frozen=True, slots=True)
class PairSet:
    """Estimate pose pairs ``(i, j)`` about one window apart, both ends on the reference."""

    i: IntArray
    j: IntArray
    lag: int


def make_pairs(
    estimate: Trajectory,
    sampler: PoseSampler,
    *,
    offset_ns: int,
    window_s: float,
    margin_s: float,
    max_pairs: int,
) -> PairSet:
    """Pair each estimate pose with the first one ``window_s`` later (both valid).

    Returns pairs thinned to at most ``max_pairs`` (every k-th start), and the HAC lag in
    pairs that covers the window's overlap.
    """
    stamps = estimate.stamps_ns
    t_s = (stamps - sampler.origin_ns + offset_ns).astype(np.float64) / NS_PER_S
    ok = sampler.valid(t_s, margin_s=margin_s)
    window_ns = round(window_s * NS_PER_S)
    j = np.searchsorted(stamps, stamps + window_ns, side="left")
    i = np.arange(stamps.shape[0])
    keep = j < stamps.shape[0]
    i, j = i[keep], j[keep]
    span = stamps[j] - stamps[i]
    keep = ok[i] & ok[j] & (span <= 2 * window_ns)
    i, j = i[keep], j[keep]
    stride = max(1, int(np.ceil(i.shape[0] / max_pairs)))
    i, j = i[::stride], j[::stride]
    per_window = max(1.0, float(np.median(j - i)) if i.size else 1.0)
    lag = int(np.ceil(2.0 * per_window / stride)) + 2
    return PairSet(i=i, j=j, lag=lag)


def fit_relative_motions(
    sampler: PoseSampler,
    estimate: Trajectory,
    pairs: PairSet,
    *,
    offset_ns: int,
    rotation0: FloatArray,
    translation0: FloatArray,
    scale0: float,
    fit_offset: bool,
    fit_translation: bool,
    fit_scale: bool,
    fixed_rotation_axes: tuple[int, ...] = (),
    fixed_translation_axes: tuple[int, ...] = (),
) -> RelativeFit:
    """Robust least squares of ``A X = X B`` over the pairs, optionally with the offset.

    ``A`` is the reference body's motion between ``t_i + offset`` and ``t_j + offset``,
    ``B`` the estimate's between ``t_i`` and ``t_j``. Residuals per pair: the rotation
    ``log((A_R X_R)^T X_R B_R)`` (radians) and, with ``fit_translation``, the translation
    ``A_R t_X + t_A - s X_R t_B - t_X`` (metres); each group is divided by its robust scale
    (two passes), the loss is soft-L1, and the covariance is the HAC sandwich.
    """
    assert estimate.quat_xyzw is not None  # noqa: S101  (callers check)
    est_q = estimate.quat_xyzw
    est_p = estimate.positions_xyz
    b_q, b_t = relative_motions(est_p, est_q, pairs.i, pairs.j)
    t_i_s = (estimate.stamps_ns[pairs.i] - sampler.origin_ns + offset_ns).astype(
        np.float64
    ) / NS_PER_S
    t_j_s = (estimate.stamps_ns[pairs.j] - sampler.origin_ns + offset_ns).astype(
        np.float64
    ) / NS_PER_S
    n = pairs.i.shape[0]
    cache: dict[float, tuple[FloatArray, FloatArray]] = {}

    def motions_a(d_s: float) -> tuple[FloatArray, FloatArray]:
        # Only the offset moves the reference; the Jacobian's other columns reuse this.
        hit = cache.get(d_s)
        if hit is None:
            times = np.concatenate((t_i_s + d_s, t_j_s + d_s))
            p = sampler.positions_at(times)
            q = sampler.quat_at(times)
            idx = np.arange(n)
            hit = relative_motions(p, q, idx, idx + n)
            if len(cache) > 4:
                cache.clear()
            cache[d_s] = hit
        return hit

    free = np.ones(8, dtype=bool)
    free[0] = fit_offset
    for k in fixed_rotation_axes:
        free[1 + k] = False
    if not fit_translation:
        free[4:7] = False
    for k in fixed_translation_axes:
        free[4 + k] = False
    free[7] = fit_scale and fit_translation
    base = np.concatenate(([0.0], np.zeros(3), translation0, [np.log(scale0)]))
    r0 = Rotation.from_matrix(rotation0)

    def unpack(x: FloatArray) -> FloatArray:
        full = base.copy()
        full[free] = x
        return full

    def raw_residuals(full: FloatArray) -> tuple[FloatArray, FloatArray]:
        a_q, a_t = motions_a(float(full[0]))
        rot_x = Rotation.from_rotvec(full[1:4]) * r0
        qx = np.broadcast_to(rot_x.as_quat(), (n, 4))
        mx = rot_x.as_matrix()
        lhs = compose_quat(a_q, qx)
        rhs = compose_quat(qx, b_q)
        r_rot = rotvec_of(compose_quat(conjugate_quat(lhs), rhs))
        if not fit_translation:
            return r_rot, np.zeros((n, 0))
        t_x = full[4:7]
        r_t = rotate(a_q, np.broadcast_to(t_x, (n, 3))) + a_t - np.exp(full[7]) * (b_t @ mx.T) - t_x
        return r_rot, r_t

    scales = np.array([0.01, 0.005])

    def weighted(x: FloatArray) -> FloatArray:
        r_rot, r_t = raw_residuals(unpack(x))
        out: FloatArray = np.concatenate((r_rot / scales[0], r_t / scales[1]), axis=1).ravel()
        return out

    x = base[free]
    idx = np.arange(8)[free]
    step = np.where(idx == 0, 1e-5, 1e-6)
    tol = np.where(idx == 0, 1e-7, 1e-7)
    for iteration in range(MAX_ITERATIONS):
        # Gauss-Newton with Huber weights (IRLS), started near the solution by the closed
        # form; each iteration costs P + 2 residual evaluations and two interpolations.
        r = weighted(x)
        jac = _jacobian(weighted, x, step, r)
        sw = np.sqrt(_huber_weights(r))
        dx = -np.linalg.lstsq(jac * sw[:, None], r * sw, rcond=None)[0]
        cost = _huber_cost(r)
        for _halving in range(6):
            if _huber_cost(weighted(x + dx)) <= cost:
                break
            dx = 0.5 * dx
        x = x + dx
        if iteration < RESCALE_ITERATIONS:
            # The groups' noise levels from the residuals (then held, so the cost is fixed).
            r_rot, r_t = raw_residuals(unpack(x))
            scales = np.array(
                [
                    max(_robust_rms(r_rot), 1e-6),
                    max(_robust_rms(r_t), 1e-7) if fit_translation else 1.0,
                ]
            )
        elif (np.abs(dx) < tol).all():
            break
    r = weighted(x)
    jac = _jacobian(weighted, x, step, r)
    sw = np.sqrt(_huber_weights(r))
    cov_free, inflation = hac_covariance(jac * sw[:, None], r * sw, n, lag=pairs.lag)
    cov = np.full((8, 8), np.nan)
    cov[np.ix_(free, free)] = cov_free
    full = unpack(x)
    rotation = (Rotation.from_rotvec(full[1:4]) * r0).as_matrix()
    r_rot, r_t = raw_residuals(full)
    return RelativeFit(
        offset_s=float(full[0]),
        rotation=rotation,
        translation_m=full[4:7].copy(),
        scale=float(np.exp(full[7])),
        cov=cov,
        pairs=n,
        rms_rotation_rad=float(np.sqrt(np.mean(r_rot**2))),
        rms_translation_m=float(np.sqrt(np.mean(r_t**2))) if fit_translation else 0.0,
        correlation_inflation=inflation,
    )


def _robust_rms(r: FloatArray) -> float:
    """RMS per component from the median absolute deviation (outliers do not inflate it)."""
    if r.size == 0:
        return 1.0
    return float(1.4826 * np.median(np.abs(r - np.median(r, axis=0))))


def _huber_weights(z: FloatArray) -> FloatArray:
    """IRLS weights of Huber's loss at ``HUBER_K`` robust sigmas."""
    a = np.abs(z)
    out: FloatArray = np.where(a <= HUBER_K, 1.0, HUBER_K / np.maximum(a, 1e-300))
    return out


def _huber_cost(z: FloatArray) -> float:
    a = np.abs(z)
    return float(np.where(a <= HUBER_K, 0.5 * a * a, HUBER_K * (a - 0.5 * HUBER_K)).sum())


def _jacobian(
    fun: Callable[[FloatArray], FloatArray], x: FloatArray, step: FloatArray, f0: FloatArray
) -> FloatArray:
    """Forward-difference Jacobian (the offset's column costs one interpolation)."""
    cols = []
    for k in range(x.shape[0]):  # a loop over the (at most 8) parameters
        dx = np.zeros_like(x)
        dx[k] = step[k]
        cols.append((fun(x + dx) - f0) / step[k])
    out: FloatArray = np.stack(cols, axis=1)
    return out


def initial_rotation(
    sampler: PoseSampler, estimate: Trajectory, i: IntArray, j: IntArray, *, offset_ns: int
) -> FloatArray:
    """Closed-form device rotation from the rotation axes of the relative motions."""
    assert estimate.quat_xyzw is not None  # noqa: S101
    t_s = (estimate.stamps_ns - sampler.origin_ns + offset_ns).astype(np.float64) / NS_PER_S
    idx = np.concatenate((i, j))
    q_ref = np.zeros((estimate.quat_xyzw.shape[0], 4))
    q_ref[idx] = sampler.quat_at(t_s[idx])
    p_ref = np.zeros((estimate.quat_xyzw.shape[0], 3))
    a_q, _ = relative_motions(p_ref, q_ref, i, j)
    b_q, _ = relative_motions(estimate.positions_xyz, estimate.quat_xyzw, i, j)
    return solve_rotation(rotvec_of(a_q), rotvec_of(b_q))


def rotation_excitation(alpha: FloatArray) -> FloatArray:
    """``mean(|a|² I - a a^T)`` over rotation vectors: the information on a left rotation."""
    sq = (alpha**2).sum(axis=1)
    out: FloatArray = np.eye(3) * sq.mean() - alpha.T @ alpha / alpha.shape[0]
    return out


def weak_axes(info: FloatArray, *, threshold: float) -> list[int]:
    """Body axes that lie mostly in the span of the information's small eigenvalues.

    An eigenvalue below ``threshold`` times the largest is small; an axis whose squared
    projection on those eigenvectors exceeds one half is weak.
    """
    values, vectors = np.linalg.eigh(info)
    weak = values < threshold * max(float(values[-1]), 1e-300)
    if not weak.any():
        return []
    share = (vectors[:, weak] ** 2).sum(axis=1)
    return [k for k in range(3) if share[k] > 0.5]
