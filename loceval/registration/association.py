"""Association in time: pair every estimate pose with a reference pose.

Two methods, both ``O((n + m) log m)`` with :func:`numpy.searchsorted`:

- ``interpolate`` (default): the reference is interpolated at the estimate's stamps
  (linear position, SLERP orientation), as the reference-system paper's Algorithm 2 does
  (``p' = p_n + δ (p_{n+1} - p_n)`` with ``δ = (t - t_n) / (t_{n+1} - t_n)``), but never
  across the reference's tracking loss: an interval longer than ``max_gap_ns`` and than
  five of the reference's median intervals (:mod:`loceval.core.gaps`), so a 1.5 Hz AMCL
  reference is interpolated, and a motion-capture outage is not.
- ``nearest``: each estimate pose is matched to its nearest reference pose within
  ``max_dt_ns``, one-to-one (where two estimate poses pick the same reference pose, the
  closer in time keeps it), for parity with the TUM tools and evo.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import FloatArray, IntArray, StampsNs
from loceval.core.gaps import gap_threshold_ns
from loceval.core.geometry import slerp_pairs
from loceval.core.quantities import format_duration
from loceval.errors import AssociationError
from loceval.options import AssociationMethod, number_default
from loceval.trajectory import Trajectory

__all__ = [
    "DEFAULT_MAX_DT_NS",
    "DEFAULT_MAX_GAP_NS",
    "Association",
    "AssociationMethod",
    "associate",
    "association_notes",
]

DEFAULT_MAX_DT_NS = round(number_default("max_dt_s") * 1_000_000_000)
"""0.01 s: the TUM benchmark's and evo's default for nearest-stamp matching."""
_NS_PER_S = 1_000_000_000
DEFAULT_MAX_GAP_NS = round(number_default("max_gap_s") * 1_000_000_000)
"""0.1 s: a longer interval between reference poses is tracking loss, never bridged."""


@dataclass(frozen=True, slots=True, eq=False)
class Association:
    """Matched pose pairs.

    Attributes:
        reference: (M poses) the reference at the matched stamps (interpolated, or the
            nearest reference poses, then with the estimate's shifted stamps).
        estimate: (M poses) the matched estimate poses, stamps shifted by ``offset_ns``.
        estimate_index: (M,) index of each matched pose in the original estimate.
        method: the association method.
        offset_ns: time offset added to the estimate's stamps.
        max_dt_ns: nearest matching's tolerance.
        max_gap_ns: interpolation's longest bridged reference interval: the caller's
            floor, raised to five of the reference's median intervals (:mod:`loceval.core.gaps`).
        dropped_outside: estimate poses before or after the reference's coverage.
        dropped_gap: estimate poses inside a reference interval longer than ``max_gap_ns``.
        dropped_unmatched: estimate poses with no reference pose within ``max_dt_ns``
            (nearest), or that lost a shared reference pose to a closer estimate pose.
    """

    reference: Trajectory
    estimate: Trajectory
    estimate_index: IntArray
    method: AssociationMethod
    offset_ns: int
    max_dt_ns: int
    max_gap_ns: int
    dropped_outside: int
    dropped_gap: int
    dropped_unmatched: int

    def __len__(self) -> int:
        """Return the number of matched pairs."""
        return len(self.estimate)

    @property
    def dropped(self) -> int:
        """Return how many estimate poses found no reference pose."""
        return self.dropped_outside + self.dropped_gap + self.dropped_unmatched


def associate(
    reference: Trajectory,
    estimate: Trajectory,
    *,
    method: AssociationMethod = AssociationMethod.INTERPOLATE,
    max_dt_ns: int = DEFAULT_MAX_DT_NS,
    max_gap_ns: int = DEFAULT_MAX_GAP_NS,
    offset_ns: int = 0,
    min_matches: int = 3,
) -> Association:
    """Match estimate poses to reference poses in time.

    Args:
        reference: the ground truth.
        estimate: the system under evaluation.
        method: ``interpolate`` or ``nearest``.
        max_dt_ns: largest stamp difference for ``nearest``, in nanoseconds.
        max_gap_ns: shortest reference interval that ``interpolate`` may treat as
            tracking loss, in nanoseconds; a longer one is a gap only when it is also
            longer than five of the reference's median intervals (:mod:`loceval.core.gaps`).
        offset_ns: added to the estimate's stamps (the framework paper's static delay).
        min_matches: fewest pairs the caller needs (alignment and RPE need three).

    Returns:
        The matched pairs, in the estimate's time order.

    Raises:
        AssociationError: the trajectories do not overlap in time, or fewer than
            ``min_matches`` poses match.
    """
    if max_dt_ns < 0 or max_gap_ns <= 0:
        msg = (
            f"max_dt must not be negative and max_gap must be positive, got "
            f"max_dt_ns={max_dt_ns!r} and max_gap_ns={max_gap_ns!r}."
        )
        raise AssociationError(msg)
    shifted = estimate.shifted(offset_ns) if offset_ns else estimate
    t_ref = reference.stamps_ns
    t_est = shifted.stamps_ns
    max_gap_ns = gap_threshold_ns(t_ref, min_gap_ns=max_gap_ns)
    if method is AssociationMethod.NEAREST:
        est_idx, ref_pose, counts = _match_nearest(reference, t_est, max_dt_ns=max_dt_ns)
    else:
        est_idx, ref_pose, counts = _match_interpolated(reference, t_est, max_gap_ns=max_gap_ns)
    outside, gap, unmatched = counts
    if est_idx.size < min_matches:
        msg = (
            f"Only {est_idx.size} of {len(estimate)} poses of {estimate.name!r} match the "
            f"reference {reference.name!r} ({method.value}, max_dt={max_dt_ns / 1e9:g} s, "
            f"max_gap={max_gap_ns / 1e9:g} s, time offset {offset_ns / 1e9:g} s); reference "
            f"covers {_span(t_ref)}, estimate (with offset) covers {_span(t_est)}; check "
            "that both record the same run in the same clock, or set the time offset."
        )
        raise AssociationError(msg, option="time_offset_s")
    matched_est = shifted.select(est_idx)
    positions, quats = ref_pose
    matched_ref = Trajectory(
        stamps_ns=matched_est.stamps_ns,
        positions_xyz=positions,
        quat_xyzw=quats,
        name=reference.name,
        source=reference.source,
        frame_id=reference.frame_id,
        child_frame_id=reference.child_frame_id,
    )
    return Association(
        reference=matched_ref,
        estimate=matched_est,
        estimate_index=est_idx,
        method=method,
        offset_ns=int(offset_ns),
        max_dt_ns=int(max_dt_ns),
        max_gap_ns=int(max_gap_ns),
        dropped_outside=outside,
        dropped_gap=gap,
        dropped_unmatched=unmatched,
    )


_Pose = tuple[FloatArray, FloatArray | None]


def _match_interpolated(
    reference: Trajectory, t_est: StampsNs, *, max_gap_ns: int
) -> tuple[IntArray, _Pose, tuple[int, int, int]]:
    t_ref = reference.stamps_ns
    n_ref = t_ref.shape[0]
    # i1: first reference stamp >= t; an exact hit needs no neighbour.
    i1 = np.searchsorted(t_ref, t_est, side="left")
    inside = i1 < n_ref
    exact = np.zeros(t_est.shape, dtype=bool)
    exact[inside] = t_ref[i1[inside]] == t_est[inside]
    between = inside & ~exact & (i1 > 0)
    i0 = np.maximum(i1 - 1, 0)
    i1c = np.minimum(i1, n_ref - 1)
    span = t_ref[i1c] - t_ref[i0]
    bridged = between & (span <= max_gap_ns)
    ok = exact | bridged
    outside = int((~exact & ~between).sum())
    gap = int((between & ~bridged).sum())
    est_idx = np.flatnonzero(ok)

    lo = np.where(exact, i1c, i0)[est_idx]
    hi = i1c[est_idx]
    # Weights from integer nanosecond differences: exact, then one float division.
    num = (t_est[est_idx] - t_ref[lo]).astype(np.float64)
    den = (t_ref[hi] - t_ref[lo]).astype(np.float64)
    w = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    p = reference.positions_xyz
    positions = p[lo] + w[:, None] * (p[hi] - p[lo])
    quats = None
    if reference.quat_xyzw is not None:
        quats = slerp_pairs(reference.quat_xyzw[lo], reference.quat_xyzw[hi], w)
    return est_idx, (positions, quats), (outside, gap, 0)


def _match_nearest(
    reference: Trajectory, t_est: StampsNs, *, max_dt_ns: int
) -> tuple[IntArray, _Pose, tuple[int, int, int]]:
    t_ref = reference.stamps_ns
    n_ref = t_ref.shape[0]
    right = np.clip(np.searchsorted(t_ref, t_est, side="left"), 0, n_ref - 1)
    left = np.clip(right - 1, 0, n_ref - 1)
    d_right = np.abs(t_ref[right] - t_est)
    d_left = np.abs(t_est - t_ref[left])
    use_left = d_left <= d_right
    nearest = np.where(use_left, left, right)
    dt = np.where(use_left, d_left, d_right)
    within = dt <= max_dt_ns
    outside = int(((t_est < t_ref[0]) | (t_est > t_ref[-1]))[~within].sum())
    candidates = np.flatnonzero(within)
    # One-to-one: per reference pose keep the estimate pose closest in time (first on ties).
    order = np.lexsort((candidates, dt[candidates], nearest[candidates]))
    sorted_ref = nearest[candidates][order]
    first = np.diff(sorted_ref, prepend=-1) != 0
    est_idx = np.sort(candidates[order][first])
    unmatched = int(t_est.shape[0] - est_idx.size - outside)
    ref_idx = nearest[est_idx]
    quats = None if reference.quat_xyzw is None else reference.quat_xyzw[ref_idx]
    return est_idx, (reference.positions_xyz[ref_idx], quats), (outside, 0, unmatched)


def _span(stamps_ns: StampsNs) -> str:
    if stamps_ns.shape[0] == 0:
        return "nothing"
    return f"{stamps_ns[0] / 1e9:.3f} s to {stamps_ns[-1] / 1e9:.3f} s"


def association_notes(matched: Association, total: int, loss: str = "tracking loss") -> list[str]:
    """Return the warnings about the poses an association dropped (outside, gaps, unmatched).

    ``loss`` names the reference's gaps (:attr:`loceval.trajectory.Trajectory.loss_words`:
    a composed tf chain's gaps are not a tracking loss).
    """
    notes = []
    if matched.dropped_outside:
        notes.append(
            f"{matched.dropped_outside} of {total} estimate poses lie outside the "
            "reference's time range and were not evaluated."
        )
    if matched.dropped_gap:
        note = (
            f"{matched.dropped_gap} of {total} estimate poses fall in reference gaps longer "
            f"than {format_duration(matched.max_gap_ns / _NS_PER_S)} ({loss}) and were not "
            "evaluated."
        )
        if matched.dropped_gap > total // 2:
            note += (
                " Most poses were dropped: if the reference is sparse by design (AMCL, "
                "surveyed points), match nearest poses within a maximum time difference, or "
                "allow a larger gap."
            )
        notes.append(note)
    if matched.dropped_unmatched:
        notes.append(
            f"{matched.dropped_unmatched} of {total} estimate poses have no reference pose "
            f"within {format_duration(matched.max_dt_ns / _NS_PER_S)} and were not evaluated."
        )
    return notes
