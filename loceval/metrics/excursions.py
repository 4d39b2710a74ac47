"""Drift outside the tracked room: what an estimate does while the reference is lost.

The framework paper's motion capture covers one room; a multi-room run starts and ends in
it, and "some fundamental assessments can still be made". An *excursion* is a reference
tracking loss (:mod:`loceval.core.gaps`) longer than ``min_excursion_s`` during which the
estimate goes on publishing. For each, the error just before leaving (the last matched
pose before the loss) and just after coming back (the first matched pose after it) and
the estimate's path length outside give the drift per metre travelled:
``(error_after_m - error_before_m) / path_length_m``. Aligning on the first stay in the
room only (``align_first`` up to the first excursion) keeps the alignment from spreading
the re-entry error over the whole run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import FloatArray, StampsNs
from loceval.core.geometry import SimilarityTransform
from loceval.core.norms import row_norms
from loceval.trajectory import Trajectory

__all__ = ["Excursion", "find_excursions"]

_NS_PER_S = 1_000_000_000
_MIN_POSES_OUTSIDE = 2


@dataclass(frozen=True, slots=True)
class Excursion:
    """One stretch outside the tracked room.

    Attributes:
        start_ns: the reference's last stamp before the loss.
        end_ns: its first stamp after it.
        path_length_m: the estimate's path length outside (aligned), metres.
        error_before_m: the ATE at the last matched pose before leaving, metres.
        error_after_m: the ATE at the first matched pose after coming back, metres.
    """

    start_ns: int
    end_ns: int
    path_length_m: float
    error_before_m: float | None
    error_after_m: float | None

    @property
    def drift_per_m(self) -> float | None:
        """``(error_after_m - error_before_m) / path_length_m``, or None when undefined."""
        if self.error_before_m is None or self.error_after_m is None:
            return None
        if self.path_length_m <= 0.0:
            return None
        return (self.error_after_m - self.error_before_m) / self.path_length_m

    def to_dict(self, t0_ns: int) -> dict[str, float | None]:
        """Return the result document's record, times in seconds since ``t0_ns``."""
        return {
            "start_s": (self.start_ns - t0_ns) / _NS_PER_S,
            "duration_s": (self.end_ns - self.start_ns) / _NS_PER_S,
            "path_length_m": self.path_length_m,
            "error_before_m": self.error_before_m,
            "error_after_m": self.error_after_m,
            "drift_per_m": self.drift_per_m,
        }


def find_excursions(
    losses_ns: list[tuple[int, int]],
    estimate: Trajectory,
    transform: SimilarityTransform,
    matched_stamps_ns: StampsNs,
    errors_m: FloatArray,
    *,
    min_excursion_s: float,
    offset_ns: int = 0,
) -> tuple[Excursion, ...]:
    """Find the excursions of one estimate.

    Args:
        losses_ns: the reference's tracking losses ``(start_ns, end_ns)``.
        estimate: the estimate as read (its own stamps).
        transform: the alignment (estimate frame -> reference frame).
        matched_stamps_ns: (M,) the matched poses' stamps (reference time), increasing.
        errors_m: (M,) the ATE translation errors of those poses.
        min_excursion_s: the shortest loss that counts, seconds.
        offset_ns: added to the estimate's stamps (the time offset).

    Returns:
        The excursions, in time order.
    """
    stamps = estimate.stamps_ns + np.int64(offset_ns)
    xyz = transform.apply_positions(estimate.positions_xyz)
    step = row_norms(np.diff(xyz, axis=0))
    walked = np.concatenate([[0.0], np.cumsum(step)])
    min_ns = round(min_excursion_s * _NS_PER_S)
    out = []
    for start, end in losses_ns:  # one iteration per tracking loss, not per pose
        if end - start <= min_ns:
            continue
        first = int(np.searchsorted(stamps, start, side="right"))
        back = int(np.searchsorted(stamps, end, side="left"))
        if back - first < _MIN_POSES_OUTSIDE:
            continue  # the estimate stopped too: no excursion to judge
        lo, hi = max(first - 1, 0), min(back, len(stamps) - 1)
        before = np.searchsorted(matched_stamps_ns, start, side="right") - 1
        after = np.searchsorted(matched_stamps_ns, end, side="left")
        out.append(
            Excursion(
                start_ns=int(start),
                end_ns=int(end),
                path_length_m=float(walked[hi] - walked[lo]),
                error_before_m=float(errors_m[before]) if before >= 0 else None,
                error_after_m=float(errors_m[after]) if after < len(errors_m) else None,
            )
        )
    return tuple(out)
