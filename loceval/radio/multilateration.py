"""Positioning from ranges: multilateration by non-linear least squares, and Min-Max.

The reference-robot paper (§V) runs two positioning algorithms on the same nanoPAN ranges
(NLLS and Min-Max) and evaluates their positions against the reference. This module does
the same for any ranging system; each solver returns a position-only
:class:`~loceval.trajectory.Trajectory` that goes through
:func:`loceval.evaluation.evaluate` like any estimate (``align=none``: the anchors are in
building coordinates already; ``association=interpolate``: the reference is interpolated
at each epoch's stamp, never across its tracking loss; ``nearest`` suits only a reference
much denser than the epochs, with ``max_dt`` at most half its interval). In 2D the
estimate's z is the tag height, so its ATE includes the reference's height variation
unless the evaluation measures in x-y only.

**Epochs** (:func:`make_epochs`) are windows of ``epoch_s`` from the first range; an
epoch's stamp is the mean of its ranges' stamps and an anchor heard more than once in an
epoch contributes the mean of its ranges. In 2D the tag is at a known height ``h`` and a
range ``r`` to an anchor at height ``z_a`` becomes the horizontal distance
``sqrt(r² - (z_a - h)²)`` (0 when ``r < |z_a - h|``, counted). An epoch needs ``dims + 1``
anchors (3 in 2D, 4 in 3D), else it is skipped and counted.

**NLLS** (:func:`solve_nlls`) minimises ``½ Σ_i (|x - a_i| - r_i)²`` per epoch with a
Levenberg-Marquardt iteration (Marquardt's diagonal scaling, Nocedal & Wright §10.3)
batched over all epochs: ``(H + λ diag JᵀJ) δ = -Jᵀf`` is summed per epoch with
:func:`numpy.add.reduceat` and solved for every epoch at once, a step is kept only where
it lowers that epoch's cost (else λ grows tenfold), and converged epochs drop out of later
iterations. ``H`` is Gauss-Newton's ``JᵀJ`` for the first ten iterations and then,
where it is positive definite, Newton's ``JᵀJ + Σ f_i (I - u_i u_iᵀ) / |x - a_i|``:
non-line-of-sight ranges leave large residuals, for which Gauss-Newton converges only
linearly (measured on ``benchmarks/ranging.py``: 430 of 5,000 3D epochs unconverged after
50 iterations with Gauss-Newton alone, 3 with the Newton term after ten), while Newton's
steps taken from the start can jump into another basin (a mirrored position). It starts
from the linear least-squares solution of ``|x|² - 2 a_iᵀx = r_i² - |a_i|²`` in the
unknowns ``(x, |x|²)`` (the "linearisation by an extra unknown", e.g. Cheung et al. 2004,
eq. 6), which needs the same ``dims + 1`` anchors not all on one line (2D) or plane (3D);
epochs whose anchors are so placed are skipped and counted, since the position is
mirrored about that line or plane.

**Min-Max** (:func:`solve_minmax`, Langendoen & Reijers 2003) takes the centre of the
intersection of the boxes ``[a_i - r_i, a_i + r_i]``; when the boxes do not intersect
(inconsistent ranges) the centre of the crossed bounds is still returned, and counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Final

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray, StampsNs
from loceval.errors import InputError
from loceval.radio.ranging import tag_positions
from loceval.readers.radio import Ranges
from loceval.trajectory import MAX_SPAN_S, Trajectory

__all__ = [
    "DEFAULT_EPOCH_S",
    "Epochs",
    "Solver",
    "default_tag_height_m",
    "make_epochs",
    "solve_minmax",
    "solve_nlls",
    "solve_positions",
]

DEFAULT_EPOCH_S: Final = 0.1
"""Epoch length: one position per 0.1 s window of ranges."""

_NS_PER_S: Final = 1_000_000_000
_MAX_ITERATIONS: Final = 50
_STEP_TOLERANCE_M: Final = 1e-8
_GAUSS_NEWTON_ITERATIONS: Final = 10
"""Iterations with Gauss-Newton's ``JᵀJ`` before Newton's Hessian is used: far from the
minimum Newton's steps can jump to another basin (a mirrored position)."""
_COST_TOLERANCE: Final = 1e-14
"""Relative fall of the cost below which an accepted step ends the iteration (rounding)."""
_LAMBDA_START: Final = 1e-3
_LAMBDA_MAX: Final = 1e12
_DEGENERATE_RCOND: Final = 1e-10
"""Smallest accepted eigenvalue ratio of the (Jacobi-scaled) linear system: below it the
anchors of an epoch lie on one line (2D) or plane (3D)."""


class Solver(StrEnum):
    """The positioning algorithms; the value is the estimate's name."""

    NLLS = "nlls"
    MINMAX = "minmax"


@dataclass(frozen=True, slots=True, eq=False)
class Epochs:
    """Ranges grouped into epochs: one (mean) range per anchor and epoch.

    Only epochs with at least ``dims + 1`` anchors are kept.

    Attributes:
        stamps_ns: (E,) the kept epochs' stamps (mean of their ranges' stamps), increasing.
        epoch_index: (M,) the epoch of each measurement, non-decreasing.
        anchor_index: (M,) the anchor of each measurement.
        anchors_xyz: (M, dims) the anchor's coordinates (x, y in 2D), metres.
        range_m: (M,) the anchor's mean range in the epoch (horizontal in 2D), metres.
        dims: 2 or 3.
        tag_height_m: the tag's fixed height in 2D, None in 3D.
        epoch_s: the epoch length, seconds.
        total_epochs: epochs with at least one range.
        skipped: epochs with too few anchors.
        clamped: 2D ranges shorter than their anchor's height difference (taken as 0).
        source: where the ranges came from.
        warnings: what the user should know (skipped epochs, clamped ranges).
    """

    stamps_ns: StampsNs
    epoch_index: IntArray
    anchor_index: IntArray
    anchors_xyz: FloatArray
    range_m: FloatArray
    dims: int
    tag_height_m: float | None
    epoch_s: float
    total_epochs: int
    skipped: int
    clamped: int
    source: str = ""
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        """Make read-only copies of the arrays and check that their lengths agree."""
        m = int(np.shape(self.range_m)[0])
        for name in ("stamps_ns", "epoch_index", "anchor_index", "anchors_xyz", "range_m"):
            array = np.array(getattr(self, name), copy=True)
            if name != "stamps_ns" and array.shape[0] != m:
                msg = f"Epochs: {name} has {array.shape[0]} rows, the ranges {m}."
                raise InputError(msg)
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        object.__setattr__(self, "warnings", tuple(self.warnings))

    def __len__(self) -> int:
        """Return the number of kept epochs."""
        return int(self.stamps_ns.shape[0])


def default_tag_height_m(
    reference: Trajectory, tag_offset_xyz: tuple[float, float, float] | None = None
) -> float:
    """Return the median height of the tag along the reference, metres.

    Raises:
        InputError: a tag offset is given but the reference has no orientation.
    """
    return float(np.median(tag_positions(reference, tag_offset_xyz)[:, 2]))


def make_epochs(
    ranges: Ranges,
    *,
    epoch_s: float = DEFAULT_EPOCH_S,
    dims: int = 2,
    tag_height_m: float | None = None,
) -> Epochs:
    """Group ranges into epochs of ``epoch_s`` starting at the first range.

    Args:
        ranges: the measurements.
        epoch_s: the epoch length, seconds.
        dims: 2 (tag at ``tag_height_m``, horizontal distances) or 3.
        tag_height_m: the tag's height in 2D, metres (see :func:`default_tag_height_m`).

    Returns:
        The epochs with at least ``dims + 1`` anchors.

    Raises:
        InputError: an option is out of range, 2D without a tag height, or no epoch has
            enough anchors.
    """
    _check_options(epoch_s=epoch_s, dims=dims, tag_height_m=tag_height_m)
    if not len(ranges):
        msg = f"No range measurements in {ranges.source!r} to position from; check the file."
        raise InputError(msg)
    epoch_ns = max(round(epoch_s * _NS_PER_S), 1)
    k = len(ranges.anchors)
    stamps = ranges.stamps_ns
    rel_ns = stamps - stamps[0]
    window = rel_ns // epoch_ns
    # Stamps are sorted, so windows are too: number the non-empty ones 0..E-1.
    first = np.concatenate(([True], np.diff(window) != 0))
    epoch_all = np.cumsum(first) - 1
    n_epochs = int(epoch_all[-1]) + 1
    count = np.bincount(epoch_all, minlength=n_epochs)
    mean_rel = np.bincount(epoch_all, weights=rel_ns.astype(np.float64), minlength=n_epochs)
    stamps_all = stamps[0] + np.rint(mean_rel / count).astype(np.int64)
    # One mean range per (epoch, anchor); unique keys are sorted epoch-major.
    key = epoch_all * k + ranges.anchor_index
    pair_key, pair_of = np.unique(key, return_inverse=True)
    heard = np.bincount(pair_of)
    range_m = np.bincount(pair_of, weights=ranges.range_m) / heard
    pair_epoch = pair_key // k
    pair_anchor = pair_key % k
    anchors = ranges.anchors.positions_xyz[pair_anchor]
    clamped = 0
    height_m = None if dims == 3 or tag_height_m is None else float(tag_height_m)
    if height_m is not None:
        dz = anchors[:, 2] - height_m
        horizontal_sq = range_m * range_m - dz * dz
        short = horizontal_sq < 0
        clamped = int(short.sum())
        range_m = np.sqrt(np.where(short, 0.0, horizontal_sq))
        anchors = anchors[:, :2]
    anchors_per_epoch = np.bincount(pair_epoch, minlength=n_epochs)
    enough = anchors_per_epoch >= dims + 1
    skipped = int(n_epochs - enough.sum())
    notes: list[str] = []
    if skipped:
        notes.append(
            f"{skipped} of {n_epochs} epochs of {epoch_s:g} s skipped: fewer than {dims + 1} "
            f"anchors heard ({dims}D positioning needs {dims + 1})."
        )
    if clamped:
        notes.append(
            f"{clamped} ranges were shorter than their anchor's height above or below the tag "
            f"(at {height_m:g} m) and were taken as horizontal distance 0."
        )
    if not enough.any():
        msg = (
            f"No epoch of {epoch_s:g} s has ranges to {dims + 1} anchors "
            f"(at most {int(anchors_per_epoch.max())}); lengthen the epoch or check that the "
            "anchor ids of the ranges match the anchors file."
        )
        raise InputError(msg, option="epoch_s")
    renumber = np.cumsum(enough) - 1
    keep = enough[pair_epoch]
    return Epochs(
        stamps_ns=stamps_all[enough],
        epoch_index=renumber[pair_epoch[keep]],
        anchor_index=pair_anchor[keep],
        anchors_xyz=anchors[keep],
        range_m=range_m[keep],
        dims=dims,
        tag_height_m=height_m,
        epoch_s=float(epoch_s),
        total_epochs=n_epochs,
        skipped=skipped,
        clamped=clamped,
        source=ranges.source,
        warnings=tuple(notes),
    )


def _check_options(*, epoch_s: float, dims: int, tag_height_m: float | None) -> None:
    if dims not in (2, 3):
        msg = f"The number of dimensions must be 2 or 3, got {dims!r}."
        raise InputError(msg, option="dims")
    if not (np.isfinite(epoch_s) and 1e-9 <= epoch_s <= MAX_SPAN_S):
        msg = f"The epoch length must be a positive number of seconds, got {epoch_s!r}."
        raise InputError(msg, option="epoch_s")
    if dims == 2 and (tag_height_m is None or not np.isfinite(tag_height_m)):
        msg = (
            f"Positioning in 2D needs the tag's height in metres, got {tag_height_m!r}; "
            "give it or take the reference's median height."
        )
        raise InputError(msg, option="tag_height_m")


def solve_minmax(epochs: Epochs) -> Trajectory:
    """Position every epoch at the centre of the intersection of its anchors' range boxes.

    Args:
        epochs: the grouped ranges.

    Returns:
        A position-only trajectory named ``minmax``, one pose per epoch.
    """
    starts = _segment_starts(epochs.epoch_index, len(epochs))
    r = epochs.range_m[:, None]
    lower = np.maximum.reduceat(epochs.anchors_xyz - r, starts, axis=0)
    upper = np.minimum.reduceat(epochs.anchors_xyz + r, starts, axis=0)
    notes = list(epochs.warnings)
    empty = int((lower > upper).any(axis=1).sum())
    if empty:
        notes.append(
            f"In {empty} of {len(epochs)} epochs the range boxes do not intersect "
            "(inconsistent ranges); the centre of their crossed bounds is used."
        )
    return _trajectory(epochs, None, 0.5 * (lower + upper), Solver.MINMAX, notes)


def solve_nlls(epochs: Epochs, *, max_iterations: int = _MAX_ITERATIONS) -> Trajectory:
    """Position every epoch by non-linear least squares on its ranges (Levenberg-Marquardt).

    Args:
        epochs: the grouped ranges.
        max_iterations: most Levenberg-Marquardt iterations.

    Returns:
        A position-only trajectory named ``nlls``, one pose per epoch whose anchors are
        not all on one line (2D) or plane (3D).

    Raises:
        InputError: in every epoch the anchors lie on one line (2D) or plane (3D).
    """
    d = epochs.dims
    e = len(epochs)
    ep = epochs.epoch_index
    # Centre the coordinates: keeps |a|² of the linear start small (conditioning).
    centre = epochs.anchors_xyz.mean(axis=0)
    a = epochs.anchors_xyz - centre
    r = epochs.range_m
    x, valid = _linear_start(a, r, ep, e, d)
    notes = list(epochs.warnings)
    degenerate = int((~valid).sum())
    if degenerate == e:
        msg = (
            f"In all {e} epochs the anchors heard lie on one {'line' if d == 2 else 'plane'}, "
            "so nlls cannot tell the position from its mirror image; add an anchor off that "
            f"{'line' if d == 2 else 'plane'}."
        )
        raise InputError(msg)
    if degenerate:
        notes.append(
            f"{degenerate} of {e} epochs skipped by nlls: their anchors lie on one "
            f"{'line' if d == 2 else 'plane'}, which leaves the position mirrored."
        )
    done = _levenberg_marquardt(x, a, r, ep, done=~valid, max_iterations=max_iterations)
    unconverged = int((~done).sum())
    if unconverged:
        notes.append(
            f"nlls did not converge within {max_iterations} iterations in {unconverged} of "
            f"{e} epochs; their last iterate is used."
        )
    return _trajectory(epochs, valid, x[valid] + centre, Solver.NLLS, notes)


def _levenberg_marquardt(
    x: FloatArray,
    a: FloatArray,
    r: FloatArray,
    ep: IntArray,
    *,
    done: BoolArray,
    max_iterations: int,
) -> BoolArray:
    """Iterate every epoch not ``done`` from ``x`` (E, d), both updated in place.

    Returns:
        ``done``: the epochs that converged, or were done on entry.
    """
    e, d = x.shape
    damping = np.full(e, _LAMBDA_START)
    cost = _cost(x, a, r, ep, _segment_starts(ep, e))
    eye = np.eye(d)
    active = np.zeros(0, dtype=np.intp)
    ep_s, a_s, r_s, starts = ep, a, r, _segment_starts(ep, e)
    for iteration in range(max_iterations):  # each vectorised over the active epochs
        now = np.flatnonzero(~done)
        if now.size == 0:
            break
        if now.size != active.size:
            # Converged epochs drop out: later iterations only touch the others' ranges.
            active = now
            rank = np.cumsum(~done) - 1
            in_active = ~done[ep]
            ep_s, a_s, r_s = rank[ep[in_active]], a[in_active], r[in_active]
            starts = _segment_starts(ep_s, active.size)
        xa = x[active]
        newton = iteration >= _GAUSS_NEWTON_ITERATIONS
        hessian, gradient, diag = _newton_system(xa, a_s, r_s, ep_s, starts, newton=newton)
        lam = damping[active]
        lhs = hessian + (lam[:, None] * diag + 1e-12)[:, :, None] * eye
        try:
            step = np.linalg.solve(lhs, -gradient[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:  # an exactly singular system: take its least-norm step
            step = (np.linalg.pinv(lhs) @ -gradient[:, :, None])[:, :, 0]
        trial = xa + step
        trial_cost = _cost(trial, a_s, r_s, ep_s, starts)
        before = cost[active]
        better = trial_cost <= before
        x[active[better]] = trial[better]
        cost[active[better]] = trial_cost[better]
        lam = np.where(better, lam / 10.0, np.minimum(lam * 10.0, _LAMBDA_MAX))
        damping[active] = lam
        # Converged: the step is below the tolerance (accepted or not, it cannot move the
        # position further), the cost stopped falling, or the damping ran out.
        small = np.abs(step).max(axis=1) < _STEP_TOLERANCE_M
        flat = better & (before - trial_cost <= _COST_TOLERANCE * before)
        done[active] = small | flat | (lam >= _LAMBDA_MAX) | (cost[active] == 0.0)
    return done


def solve_positions(
    ranges: Ranges,
    *,
    solvers: tuple[Solver, ...] = (Solver.NLLS, Solver.MINMAX),
    epoch_s: float = DEFAULT_EPOCH_S,
    dims: int = 2,
    tag_height_m: float | None = None,
    reference: Trajectory | None = None,
    tag_offset_xyz: tuple[float, float, float] | None = None,
) -> tuple[Trajectory, ...]:
    """Group ranges into epochs and run each solver on them.

    Args:
        ranges: the measurements.
        solvers: the algorithms to run, in output order.
        epoch_s: the epoch length, seconds.
        dims: 2 or 3.
        tag_height_m: the tag's height in 2D, metres; None takes the reference's median
            tag height.
        reference: the ground truth, for the default tag height.
        tag_offset_xyz: the tag in the reference body frame, for the default tag height.

    Returns:
        One position-only trajectory per solver, named after it.

    Raises:
        InputError: an option is out of range, 2D without a tag height or reference, or
            no epoch has enough anchors.
    """
    if dims == 2 and tag_height_m is None and reference is not None:
        tag_height_m = default_tag_height_m(reference, tag_offset_xyz)
    epochs = make_epochs(ranges, epoch_s=epoch_s, dims=dims, tag_height_m=tag_height_m)
    run = {Solver.NLLS: solve_nlls, Solver.MINMAX: solve_minmax}
    return tuple(run[Solver(s)](epochs) for s in solvers)


def _linear_start(
    a: FloatArray, r: FloatArray, ep: IntArray, e: int, d: int
) -> tuple[FloatArray, BoolArray]:
    """Solve ``[-2aᵀ 1] [x; |x|²] = r² - |a|²`` per epoch by batched normal equations."""
    h = np.concatenate((-2.0 * a, np.ones((a.shape[0], 1))), axis=1)  # (M, d + 1)
    b = r * r - (a * a).sum(axis=1)
    p = d + 1
    hth = np.empty((e, p, p))
    htb = np.empty((e, p))
    for i in range(p):  # (d + 1)² sums, each over all measurements
        htb[:, i] = np.bincount(ep, weights=h[:, i] * b, minlength=e)
        for j in range(i, p):
            hth[:, i, j] = hth[:, j, i] = np.bincount(ep, weights=h[:, i] * h[:, j], minlength=e)
    # Jacobi scaling, then the eigenvalue ratio tells a line / plane of anchors.
    scale = 1.0 / np.sqrt(np.maximum(np.einsum("eii->ei", hth), 1e-300))
    scaled = hth * scale[:, :, None] * scale[:, None, :]
    eig = np.linalg.eigvalsh(scaled)
    valid = eig[:, 0] > _DEGENERATE_RCOND * eig[:, -1]
    scaled[~valid] = np.eye(p)
    solution = np.linalg.solve(scaled, (htb * scale)[:, :, None])[:, :, 0] * scale
    x: FloatArray = solution[:, :d].copy()
    x[~valid] = 0.0
    return x, valid


def _segment_starts(ep: IntArray, e: int) -> IntArray:
    """Return where each of the ``e`` epochs starts in the epoch-sorted measurements."""
    counts = np.bincount(ep, minlength=e)
    out: IntArray = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.intp)
    return out


def _cost(
    x: FloatArray, a: FloatArray, r: FloatArray, ep: IntArray, starts: IntArray
) -> FloatArray:
    """Return the (E,) sums of squared range residuals at positions ``x`` (E, d)."""
    diff = x[ep] - a
    f = np.sqrt((diff * diff).sum(axis=1)) - r
    out: FloatArray = np.add.reduceat(f * f, starts)
    return out


def _newton_system(
    x: FloatArray,
    a: FloatArray,
    r: FloatArray,
    ep: IntArray,
    starts: IntArray,
    *,
    newton: bool,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the Hessian (E, d, d), gradient ``Jᵀf`` (E, d) and ``diag JᵀJ`` (E, d) per epoch.

    For ``½ Σ f_i²`` with ``f_i = |x - a_i| - r_i``. The Hessian is Gauss-Newton's ``JᵀJ``
    unless ``newton``, then Newton's where that is positive definite.

    The measurements are sorted by epoch, so each sum is one :func:`numpy.add.reduceat`.
    """
    diff = x[ep] - a
    dist = np.sqrt((diff * diff).sum(axis=1))
    safe = np.maximum(dist, 1e-12)
    jac = diff / safe[:, None]  # unit vectors anchor -> tag
    f = dist - r
    outer = jac[:, :, None] * jac[:, None, :]
    hessian: FloatArray = np.add.reduceat(outer, starts, axis=0)
    if newton:
        # Newton's Hessian of ½Σf²: JᵀJ + Σ f_i ∇²f_i, ∇²f_i = (I - u_i u_iᵀ) / |x - a_i|.
        curvature = (f / safe)[:, None, None] * (np.eye(x.shape[1]) - outer)
        full = hessian + np.add.reduceat(curvature, starts, axis=0)
        convex = np.linalg.eigvalsh(full)[:, 0] > 0
        hessian[convex] = full[convex]
    gradient: FloatArray = np.add.reduceat(jac * f[:, None], starts, axis=0)
    scale: FloatArray = np.add.reduceat(jac * jac, starts, axis=0)  # diag JᵀJ, positive
    return hessian, gradient, scale


def _trajectory(
    epochs: Epochs, keep: BoolArray | None, positions: FloatArray, solver: Solver, notes: list[str]
) -> Trajectory:
    """Return the solver's estimate: the kept epochs' stamps and positions (z fixed in 2D)."""
    stamps = epochs.stamps_ns if keep is None else epochs.stamps_ns[keep]
    if epochs.tag_height_m is not None:
        positions = np.column_stack((positions, np.full(stamps.shape[0], epochs.tag_height_m)))
    return Trajectory(
        stamps_ns=stamps,
        positions_xyz=positions,
        name=solver.value,
        source=epochs.source,
        warnings=tuple(notes),
    )
