"""Tracking loss, judged against each source's own rate.

A source that publishes at 100 Hz and goes quiet for a second has lost tracking; AMCL,
which publishes about 1.5 times a second (and only after the robot moved), has not. So an
interval between two poses is a *tracking loss* when it is longer than both

- the floor ``min_gap_ns`` (the evaluation's maximum gap, 0.1 s by default: a
  motion-capture system at 120 Hz that misses 0.1 s has lost the body), and
- :data:`GAP_RATE_FACTOR` (5) times the source's median interval.

Why five: a source at a steady rate that misses up to four samples in a row (network
jitter, a bag writer's full queue, a skipped filter update) still follows the body, and the
interpolation across such an interval is as good as the source; five or more missing
samples in a row is a stretch the source did not see. On the public recordings this keeps
every real outage (fr2_desk's 27 motion-capture losses, the longest 12 s; AMCL's 9.3 s
standstill in nav2_turtlebot) and drops the hundreds of ordinary intervals the fixed 0.1 s
rule called gaps (AMCL: 134 -> 1; ``ROS_example.bag`` S-PTAM at 7.7 Hz: 5438 -> 0).

Every consumer (association's "never bridge a gap" rule, the evaluation's warnings and its
``reference.gaps``, the report's plots and the CAD writers' path splits) asks this module,
so they all agree on where a path breaks.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from loceval.core.arrays import BoolArray, IntArray, StampsNs
from loceval.core.quantiles import median

__all__ = [
    "GAP_RATE_FACTOR",
    "gap_threshold_ns",
    "loss_indices",
    "path_breaks",
    "tracking_losses",
]

GAP_RATE_FACTOR = 5
"""An interval longer than this many median intervals of its source is tracking loss."""


def gap_threshold_ns(stamps_ns: StampsNs, *, min_gap_ns: int) -> int:
    """Return the longest interval between poses of this source that is not a gap.

    Args:
        stamps_ns: (N,) int64 strictly increasing stamps of one source.
        min_gap_ns: the floor, in nanoseconds (the evaluation's maximum gap).

    Returns:
        ``max(min_gap_ns, GAP_RATE_FACTOR * median interval)`` in nanoseconds; the floor
        alone for fewer than two stamps.
    """
    if stamps_ns.shape[0] < 2:
        return int(min_gap_ns)
    median_ns = median(np.diff(stamps_ns))
    return max(int(min_gap_ns), round(GAP_RATE_FACTOR * median_ns))


def loss_indices(stamps_ns: StampsNs, *, min_gap_ns: int) -> IntArray:
    """Return the indices ``i`` whose interval ``stamps_ns[i] -> stamps_ns[i + 1]`` is a gap.

    Args:
        stamps_ns: (N,) int64 strictly increasing stamps of one source.
        min_gap_ns: the floor, in nanoseconds (see :func:`gap_threshold_ns`).

    Returns:
        (K,) increasing indices into ``stamps_ns[:-1]``.
    """
    if stamps_ns.shape[0] < 2:
        return np.zeros(0, dtype=np.intp)
    threshold = gap_threshold_ns(stamps_ns, min_gap_ns=min_gap_ns)
    out: IntArray = np.flatnonzero(np.diff(stamps_ns) > threshold)
    return out


def tracking_losses(stamps_ns: StampsNs, *, min_gap_ns: int) -> list[tuple[int, int]]:
    """Return the ``(start_ns, end_ns)`` of every tracking loss of one source.

    Args:
        stamps_ns: (N,) int64 strictly increasing stamps of one source.
        min_gap_ns: the floor, in nanoseconds (see :func:`gap_threshold_ns`).

    Returns:
        The last stamp before and the first stamp after each loss, in time order.
    """
    idx = loss_indices(stamps_ns, min_gap_ns=min_gap_ns)
    return [(int(stamps_ns[i]), int(stamps_ns[i + 1])) for i in idx]


def path_breaks(
    stamps_ns: StampsNs, *, min_gap_ns: int, losses: Sequence[tuple[int, int]] = ()
) -> BoolArray:
    """Return where a drawn path must break: its own tracking loss or the reference's.

    A path (the reference, or an aligned estimate at its matched stamps) is drawn as one
    line per continuous piece. It breaks after pose ``i`` when the interval to pose
    ``i + 1`` is a tracking loss of its own (:func:`loss_indices`) or overlaps one of
    ``losses`` (the reference's tracking losses: the estimate poses inside one were not
    evaluated, so a line across it would be a chord nobody measured).

    Args:
        stamps_ns: (N,) int64 strictly increasing stamps of the path.
        min_gap_ns: the floor of the path's own threshold (see :func:`gap_threshold_ns`).
        losses: ``(start_ns, end_ns)`` intervals in time order that never overlap, such
            as :func:`tracking_losses` of the reference.

    Returns:
        (max(N - 1, 0),) True after each pose that ends a piece.
    """
    n = int(stamps_ns.shape[0])
    out: BoolArray = np.zeros(max(n - 1, 0), dtype=bool)
    if n < 2:
        return out
    out[loss_indices(stamps_ns, min_gap_ns=min_gap_ns)] = True
    if losses:
        spans = np.asarray(losses, dtype=np.int64).reshape(-1, 2)
        # interval (s_i, s_i+1) overlaps loss (a, b) when a < s_i+1 and b > s_i
        started = np.searchsorted(spans[:, 0], stamps_ns[1:], side="left")
        ended = np.searchsorted(spans[:, 1], stamps_ns[:-1], side="right")
        out |= started > ended
    return out
