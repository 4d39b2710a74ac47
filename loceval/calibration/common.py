"""Shared machinery of the clock and device-offset estimation (private).

- :class:`PoseSampler`: the reference interpolated at float times (seconds after its first
  pose), linear positions and SLERP orientations, with a mask that never bridges a gap.
- :func:`hac_covariance`: the sandwich covariance of an M-estimate whose residuals are
  correlated in time up to a known lag (neighbours share interpolation, position fits share
  drift), times a safety factor measured by Monte Carlo (see SIGMA_SAFETY).
- :func:`fit_relative_motions`: the robust nonlinear least squares over relative motions
  ``A X = X B`` of short windows, jointly with the time offset (see
  :mod:`loceval.calibration.handeye`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray
from loceval.core.geometry import compose_quat, conjugate_quat, skew
from loceval.core.quantiles import median
from loceval.core.rotation import Rotation
from loceval.trajectory import Trajectory

NS_PER_S = 1_000_000_000
MAX_ITERATIONS = 30
CONVERGED = 1e-6
"""Largest step at convergence: 1 µs, 1 µrad, 1 µm (far below any sigma)."""
RESCALE_ITERATIONS = 2
ANCHOR_STEP_S = 1e-4
RELINEARISE_S = 5e-4
SIGMA_SAFETY = 1.5
"""Factor on the sandwich sigmas of :func:`fit_relative_motions`. Measured on 12 seeds of
the synthetic handheld recordings (tests/calibration_factory.py, 60 s): the true errors had
an RMS of 0.8 to 1.35 sandwich sigmas per component (up to 3.5 for one), the estimated
meat being noisy with a few fast, high-leverage windows; an interval that misses is worse
than one 1.5 times wider, which is still a small fraction of the tolerances."""
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

    @classmethod
    def from_start(cls, trajectory: Trajectory, *, max_gap_ns: int) -> PoseSampler:
        """Return the sampler whose times count from the trajectory's first stamp."""
        return cls(trajectory, origin_ns=int(trajectory.stamps_ns[0]), max_gap_ns=max_gap_ns)

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
    jac: FloatArray,
    psi: FloatArray,
    groups: int,
    *,
    lag: int,
    dpsi: FloatArray | None = None,
) -> tuple[FloatArray, float]:
    """Sandwich covariance of (M-estimated) least-squares parameters, residuals correlated.

    Rows come in ``groups`` consecutive blocks of equal size (one block per time step); the
    score of each block is ``J_b^T psi_b``, and their autocovariance up to ``lag`` blocks is
    summed with uniform weights into ``M`` (a truncated kernel: the residuals here are
    correlated up to a known lag, and Newey and West's Bartlett weights would shrink exactly
    that correlation). The bread is ``A = J^T diag(psi') J``: for Huber's loss ``psi' = 0``
    on clipped residuals, which then carry no curvature (the IRLS weights there would claim
    information those residuals do not give).

    Args:
        jac: (R, P) Jacobian of the scaled residuals.
        psi: (R,) influence of each scaled residual (the residual itself for least squares).
        groups: number of blocks (R must be a multiple).
        lag: largest block lag whose correlation is counted.
        dpsi: (R,) derivative of the influence (None: all ones, plain least squares).

    Returns:
        The (P, P) covariance ``A^-1 M A^-1`` and the ratio of its variances to those of
        the naive ``A^-1 s²`` (averaged over parameters; how much correlation inflated it).
    """
    p = jac.shape[1]
    scores = (jac * psi[:, None]).reshape(groups, -1, p).sum(axis=1)
    lags = range(1, min(lag, groups - 1) + 1)
    autocov = [scores[:-k].T @ scores[k:] for k in lags]  # a loop over lags, not over poses
    meat = scores.T @ scores + sum((c + c.T for c in autocov), np.zeros((p, p)))
    curv = jac if dpsi is None else jac * dpsi[:, None]
    values, vectors = np.linalg.eigh(0.5 * (meat + meat.T))
    if values.min() < -1e-9 * max(abs(values.max()), 1e-300):
        # The uniform kernel left an indefinite sum (a long lag over few blocks, whose
        # estimated autocovariances are noisy): its positive part could be 0, a sigma of
        # 0. Bartlett's weights (Newey and West 1987) cannot make it indefinite.
        weights = [1.0 - k / (len(autocov) + 1) for k in lags]
        meat = scores.T @ scores + sum(
            (w * (c + c.T) for w, c in zip(weights, autocov, strict=True)), np.zeros((p, p))
        )
        values, vectors = np.linalg.eigh(0.5 * (meat + meat.T))
    meat = (vectors * np.maximum(values, 0.0)) @ vectors.T
    bread = np.linalg.pinv(jac.T @ curv)
    cov: FloatArray = bread @ meat @ bread
    dof = max(psi.shape[0] - p, 1)
    naive = bread * float(psi @ psi) / dof
    ratio = float(np.mean(np.diag(cov) / np.maximum(np.diag(naive), 1e-300)))
    return cov, ratio


def rotvec_of(quat_xyzw: FloatArray) -> FloatArray:
    """Return (N, 3) rotation vectors (radians) of (N, 4) unit quaternions."""
    return Rotation.from_quat(quat_xyzw).as_rotvec()


def quat_of(rotvec: FloatArray) -> FloatArray:
    """Return (N, 4) unit quaternions x y z w of (N, 3) rotation vectors (radians)."""
    return Rotation.from_rotvec(rotvec).as_quat()


def rotate(quat_xyzw: FloatArray, vectors: FloatArray) -> FloatArray:
    """Rotate matching rows: (N, 3) vectors by (N, 4) unit quaternions."""
    return Rotation.from_quat(quat_xyzw).apply(vectors)


def slerp(q0_xyzw: FloatArray, q1_xyzw: FloatArray, weights: FloatArray) -> FloatArray:
    """SLERP between matching rows (as :func:`loceval.core.geometry.slerp_pairs`, in numpy)."""
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

    ``cov`` is over ``[offset_s, rx, ry, rz, tx, ty, tz, log_scale, vx, vy, vz]``
    (rotation as a left perturbation about the reference body's axes, radians; drift
    velocity in the estimate's frame, its units per second); rows and columns of fixed
    parameters are NaN.
    """

    offset_s: float
    rotation: FloatArray
    translation_m: FloatArray
    scale: float
    drift_velocity: FloatArray
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
    """Pair estimate poses ``k`` poses (about ``window_s``) apart, each pose in one pair.

    Poses ``[0, k)`` pair with ``[k, 2k)``, ``[2k, 3k)`` with ``[3k, 4k)``, and so on, so
    that no two pairs share a pose: with white noise per pose their residuals are then
    independent, and the sandwich covariance needs only a short lag (for the reference's
    interpolation shared by neighbours). Overlapping pairs would use each pose twice, but
    their correlation, which the covariance must then estimate from the data, made sigmas
    up to 1.3 times too small in Monte Carlo runs; this costs sqrt(2) in sigma instead.

    Returns pairs whose ends both lie on tracked reference (within ``margin_s``) and span
    at most two windows, thinned evenly to at most ``max_pairs``.
    """
    stamps = estimate.stamps_ns
    n = stamps.shape[0]
    t_s = (stamps - sampler.origin_ns + offset_ns).astype(np.float64) / NS_PER_S
    ok = sampler.valid(t_s, margin_s=margin_s)
    window_ns = round(window_s * NS_PER_S)
    dt_ns = median(np.diff(stamps)) if n > 1 else float(window_ns)
    k = max(1, round(window_ns / max(dt_ns, 1.0)))
    i = np.flatnonzero((np.arange(n) // k) % 2 == 0)
    j = i + k
    keep = j < n
    i, j = i[keep], j[keep]
    span = stamps[j] - stamps[i]
    keep = ok[i] & ok[j] & (span <= 2 * window_ns) & (span >= window_ns // 2)
    i, j = i[keep], j[keep]
    stride = max(1, int(np.ceil(i.shape[0] / max_pairs)))
    i, j = i[::stride], j[::stride]
    return PairSet(i=i, j=j, lag=3)


@dataclass(frozen=True, slots=True)
class FitOptions:
    """Which parameters :func:`fit_relative_motions` estimates (the others stay fixed)."""

    fit_offset: bool
    fit_translation: bool
    fit_scale: bool
    fit_drift: bool = True
    fixed_rotation_axes: tuple[int, ...] = ()
    fixed_translation_axes: tuple[int, ...] = ()


@dataclass(frozen=True, slots=True)
class _Anchor:
    """The reference's motions at offset ``d_s`` and their rate of change with it."""

    d_s: float
    q: FloatArray
    t: FloatArray
    w: FloatArray
    v: FloatArray


_N_PAR = 11  # offset, rotation (3), translation (3), log scale, drift velocity (3)


class _RelativeProblem:
    """Residuals and Jacobian of ``A X = X B`` over the pairs (see fit_relative_motions).

    Parameters (full vector of 11): ``[offset_s, phi (3), t_X (3), log s, v (3)]``, with
    ``X_R = exp([phi]) R_0``. The reference's motions are taken first order in the offset
    about an anchor that follows the solution: interpolating the reference anew for every
    trial offset cost most of the time on long recordings; within RELINEARISE_S of the
    anchor the neglected term is below 1e-4 degrees.
    """

    def __init__(
        self,
        sampler: PoseSampler,
        estimate: Trajectory,
        pairs: PairSet,
        *,
        offset_ns: int,
        rotation0: FloatArray,
        with_translation: bool,
    ) -> None:
        """Precompute everything that does not depend on the parameters."""
        assert estimate.quat_xyzw is not None  # noqa: S101  (callers check)
        est_q = estimate.quat_xyzw
        self.sampler = sampler
        self.n = pairs.i.shape[0]
        self.b_q, self.b_t = relative_motions(estimate.positions_xyz, est_q, pairs.i, pairs.j)
        self.b_inv = quat_matrices(conjugate_quat(est_q[pairs.i]))  # estimate -> sensor i
        self.b_mat_t = quat_matrices(self.b_q).transpose(0, 2, 1)  # R_B^T
        stamps = estimate.stamps_ns
        self.dt_s = (stamps[pairs.j] - stamps[pairs.i]).astype(np.float64) / NS_PER_S
        shift = offset_ns - sampler.origin_ns
        self.t_i_s = (stamps[pairs.i] + shift).astype(np.float64) / NS_PER_S
        self.t_j_s = (stamps[pairs.j] + shift).astype(np.float64) / NS_PER_S
        self.r0 = Rotation.from_matrix(rotation0)
        self.with_translation = with_translation
        self.rows = 6 if with_translation else 3
        self.scales = np.array([0.01, 0.005])
        self.anchor: _Anchor | None = None

    def _exact_a(self, d_s: float) -> tuple[FloatArray, FloatArray]:
        times = np.concatenate((self.t_i_s + d_s, self.t_j_s + d_s))
        p = self.sampler.positions_at(times)
        q = self.sampler.quat_at(times)
        idx = np.arange(self.n)
        return relative_motions(p, q, idx, idx + self.n)

    def set_anchor(self, d_s: float) -> _Anchor:
        """Interpolate the reference exactly at ``d_s`` (and one small step later)."""
        q0, t0 = self._exact_a(d_s)
        qh, th = self._exact_a(d_s + ANCHOR_STEP_S)
        w = rotvec_of(compose_quat(conjugate_quat(q0), qh)) / ANCHOR_STEP_S
        self.anchor = _Anchor(d_s, q0, t0, w, (th - t0) / ANCHOR_STEP_S)
        return self.anchor

    def motions_a(self, d_s: float) -> tuple[FloatArray, FloatArray, _Anchor]:
        """The reference's motions at offset ``d_s`` (first order about the anchor)."""
        anchor = self.anchor
        if anchor is None or abs(d_s - anchor.d_s) > RELINEARISE_S:
            anchor = self.set_anchor(d_s)
        e = d_s - anchor.d_s
        if e == 0.0:
            return anchor.q, anchor.t, anchor
        return compose_quat(anchor.q, quat_of(anchor.w * e)), anchor.t + anchor.v * e, anchor

    def _travel(self, full: FloatArray, mx: FloatArray) -> FloatArray:
        """``R_X t_B'``: the estimate's travel, drift removed, in the body's frame."""
        b_t = self.b_t - np.einsum("nij,j->ni", self.b_inv, full[8:11]) * self.dt_s[:, None]
        out: FloatArray = b_t @ mx.T
        return out

    def residuals(self, full: FloatArray) -> FloatArray:
        """(n, rows) scaled residuals: rotation, then translation."""
        a_q, a_t, _ = self.motions_a(float(full[0]))
        rot_x = Rotation.from_rotvec(full[1:4]) * self.r0
        qx = np.broadcast_to(rot_x.as_quat(), (self.n, 4))
        lhs = compose_quat(a_q, qx)
        r_rot = rotvec_of(compose_quat(conjugate_quat(lhs), compose_quat(qx, self.b_q)))
        if not self.with_translation:
            out: FloatArray = r_rot / self.scales[0]
            return out
        t_x = full[4:7]
        travel = self._travel(full, rot_x.as_matrix())
        r_t = rotate(a_q, np.broadcast_to(t_x, (self.n, 3))) + a_t - np.exp(full[7]) * travel
        return np.concatenate((r_rot / self.scales[0], (r_t - t_x) / self.scales[1]), axis=1)

    def jacobian(self, full: FloatArray) -> FloatArray:
        """(n * rows, 11) analytic Jacobian, first order in the residual (under a degree).

        With ``X -> exp([phi]) X`` and ``A -> A exp([w] e)`` (the anchor's rate ``w``), the
        rotation residual moves by ``R_B^T R_X^T (I - R_A) phi - R_X^T w e``; the
        translation residual by ``s [R_X t_B']x phi`` and ``(R_A (w x t_X) + v) e``, and
        linearly in ``t_X``, ``log s`` and the drift velocity (checked against central
        differences: within 0.3 %).
        """
        n, rows, sc = self.n, self.rows, self.scales
        jac = np.zeros((n, rows, _N_PAR))
        a_q, _, anchor = self.motions_a(float(full[0]))
        ra = quat_matrices(a_q)
        mx = (Rotation.from_rotvec(full[1:4]) * self.r0).as_matrix()
        jac[:, :3, 1:4] = (self.b_mat_t @ mx.T) @ (np.eye(3) - ra) / sc[0]
        jac[:, :3, 0] = -(anchor.w @ mx) / sc[0]
        if self.with_translation:
            s = np.exp(full[7])
            travel = self._travel(full, mx)
            w_x_t = np.cross(anchor.w, full[4:7])
            jac[:, 3:, 0] = (np.einsum("nij,nj->ni", ra, w_x_t) + anchor.v) / sc[1]
            jac[:, 3:, 1:4] = s * skew(travel) / sc[1]
            jac[:, 3:, 4:7] = (ra - np.eye(3)) / sc[1]
            jac[:, 3:, 7] = -s * travel / sc[1]
            jac[:, 3:, 8:11] = (s / sc[1]) * self.dt_s[:, None, None] * (mx @ self.b_inv)
        out: FloatArray = jac.reshape(n * rows, _N_PAR)
        return out

    def rescale(self, full: FloatArray) -> None:
        """Set each group's scale to the robust RMS of its residuals at ``full``."""
        res = self.residuals(full) * np.repeat(self.scales, 3)[: self.rows]
        rot = max(_robust_rms(res[:, :3]), 1e-6)
        trans = max(_robust_rms(res[:, 3:]), 1e-7) if self.with_translation else 1.0
        self.scales = np.array([rot, trans])


def fit_relative_motions(
    sampler: PoseSampler,
    estimate: Trajectory,
    pairs: PairSet,
    *,
    offset_ns: int,
    rotation0: FloatArray,
    translation0: FloatArray,
    scale0: float,
    options: FitOptions,
) -> RelativeFit:
    """Robust least squares of ``A X = X B`` over the pairs, optionally with the offset.

    ``A`` is the reference body's motion between ``t_i + offset`` and ``t_j + offset``,
    ``B`` the estimate's between ``t_i`` and ``t_j``. Residuals per pair: the rotation
    ``log((A_R X_R)^T X_R B_R)`` (radians) and, with ``fit_translation``, the translation
    ``A_R t_X + t_A - s X_R (t_B - B_Ri^T v dt) - t_X`` (metres), where ``v`` is a constant
    drift velocity of the estimate's frame (``fit_drift``). Each group is divided by its
    robust scale, the loss is Huber's (IRLS Gauss-Newton), and the covariance is the
    sandwich of :func:`hac_covariance` times SIGMA_SAFETY.
    """
    problem = _RelativeProblem(
        sampler,
        estimate,
        pairs,
        offset_ns=offset_ns,
        rotation0=rotation0,
        with_translation=options.fit_translation,
    )
    free = _free_parameters(options)
    base = np.concatenate(([0.0], np.zeros(3), translation0, [np.log(scale0)], np.zeros(3)))

    def unpack(x: FloatArray) -> FloatArray:
        full = base.copy()
        full[free] = x
        return full

    x = base[free]
    for iteration in range(MAX_ITERATIONS):
        # Gauss-Newton with Huber weights (IRLS), started near the solution by the closed
        # forms; an iteration costs two or three residual evaluations.
        full = unpack(x)
        r = problem.residuals(full).ravel()
        jw = problem.jacobian(full)[:, free] * np.sqrt(_huber_weights(r))[:, None]
        normal = jw.T @ jw
        # Normal equations (at most 11 columns): far cheaper than an SVD of the tall
        # matrix; the tiny ridge only guards a parameter the data hardly move.
        normal += 1e-12 * np.trace(normal) * np.eye(normal.shape[0])
        dx = -np.linalg.solve(normal, jw.T @ (r * np.sqrt(_huber_weights(r))))
        cost = _huber_cost(r)
        for _halving in range(6):
            if _huber_cost(problem.residuals(unpack(x + dx))) <= cost:
                break
            dx = 0.5 * dx
        x = x + dx
        if iteration < RESCALE_ITERATIONS:
            problem.rescale(unpack(x))  # then held, so that the cost stays one function
        elif (np.abs(dx) < CONVERGED).all():
            break
    full = unpack(x)
    if options.fit_offset:
        problem.set_anchor(float(full[0]))  # residuals and Jacobian exact at the solution
    f0 = problem.residuals(full)
    r = f0.ravel()
    inside = np.abs(r) <= HUBER_K
    psi = np.where(inside, r, HUBER_K * np.sign(r))
    cov_free, inflation = hac_covariance(
        problem.jacobian(full)[:, free],
        psi,
        problem.n,
        lag=pairs.lag,
        dpsi=inside.astype(np.float64),
    )
    cov = np.full((_N_PAR, _N_PAR), np.nan)
    cov[np.ix_(free, free)] = cov_free * SIGMA_SAFETY**2
    raw = f0 * np.repeat(problem.scales, 3)[: problem.rows]
    return RelativeFit(
        offset_s=float(full[0]),
        rotation=(Rotation.from_rotvec(full[1:4]) * problem.r0).as_matrix(),
        translation_m=full[4:7].copy(),
        scale=float(np.exp(full[7])),
        drift_velocity=full[8:11].copy(),
        cov=cov,
        pairs=problem.n,
        rms_rotation_rad=float(np.sqrt(np.mean(raw[:, :3] ** 2))),
        rms_translation_m=float(np.sqrt(np.mean(raw[:, 3:] ** 2)))
        if options.fit_translation
        else 0.0,
        correlation_inflation=inflation,
    )


def _free_parameters(options: FitOptions) -> BoolArray:
    free = np.ones(_N_PAR, dtype=bool)
    free[0] = options.fit_offset
    free[[1 + k for k in options.fixed_rotation_axes]] = False
    free[4:7] = options.fit_translation
    free[[4 + k for k in options.fixed_translation_axes]] = False
    free[7] = options.fit_scale and options.fit_translation
    free[8:11] = options.fit_drift and options.fit_translation
    return free


def quat_matrices(quat_xyzw: FloatArray) -> FloatArray:
    """Return the (N, 3, 3) rotation matrices of (N, 4) unit quaternions (numpy)."""
    x, y, z, w = np.moveaxis(np.asarray(quat_xyzw, dtype=np.float64), -1, 0)
    out: FloatArray = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )
    return out


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
