"""Matching stamps as evo does: nearest in float seconds, the shorter side to the longer.

:func:`loceval.registration.association.associate` matches one-to-one in integer
nanoseconds; ``loceval ape``/``rpe`` reproduce evo's figures exactly and match its way
(learnt from evo 1.38.1's observed output, not its code).
"""

from __future__ import annotations

import numpy as np

from loceval.core.arrays import FloatArray, IntArray, StampsNs

__all__ = ["match_nearest_seconds", "seconds_of"]

_NS_PER_S = 1_000_000_000


def seconds_of(stamps_ns: StampsNs) -> FloatArray:
    """Return float seconds as a text reader parses them (rounded once, as near as can be).

    int64 nanoseconds are exact in an 80-bit long double; one division there and one
    rounding to float64 gives the float nearest the decimal stamp, all but never off by one
    unit in the last place.
    """
    exact = stamps_ns.astype(np.longdouble) / np.longdouble(_NS_PER_S)
    out: FloatArray = exact.astype(np.float64)
    return out


def match_nearest_seconds(
    reference_ns: StampsNs, estimate_ns: StampsNs, *, max_dt_s: float, offset_s: float = 0.0
) -> tuple[IntArray, IntArray]:
    """Match stamps to the nearest of the other side in float seconds (evo's way).

    The side with fewer stamps is matched to the other: each of its stamps takes the
    nearest stamp there, if within ``max_dt_s``. Unlike
    :func:`loceval.registration.association.associate` the matching is not one-to-one
    (two poses of the shorter side may share a pose of the longer), compares float
    seconds, not nanoseconds, and a stamp half-way between two (in float seconds) takes
    the earlier one.

    Args:
        reference_ns: (N,) sorted reference stamps.
        estimate_ns: (M,) sorted estimate stamps.
        max_dt_s: the largest time difference of a match, seconds.
        offset_s: added to the estimate's stamps first, seconds.

    Returns:
        ``(reference_index, estimate_index)`` of the matches, in time order; the indices
        of the shorter side (the estimate's when both are as long) increase strictly.
    """
    t_ref = seconds_of(reference_ns)
    t_est = seconds_of(estimate_ns) + offset_s
    if t_ref.shape[0] < t_est.shape[0]:
        est_idx, ref_idx = _nearest(t_est, t_ref, max_dt_s)
        return ref_idx, est_idx
    return _nearest(t_ref, t_est, max_dt_s)


def _nearest(
    targets: FloatArray, queries: FloatArray, max_dt_s: float
) -> tuple[IntArray, IntArray]:
    """Return ``(target_index, query_index)`` of each query's nearest target within reach."""
    n = targets.shape[0]
    right = np.clip(np.searchsorted(targets, queries, side="left"), 0, n - 1)
    left = np.clip(right - 1, 0, n - 1)
    d_right = np.abs(targets[right] - queries)
    d_left = np.abs(queries - targets[left])
    nearest = np.where(d_right < d_left, right, left)
    within = np.flatnonzero(np.minimum(d_left, d_right) <= max_dt_s)
    return nearest[within], within
