"""One ``loceval ape`` or ``rpe`` run: what the printout and the result zip are made of."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from loceval.core.arrays import IntArray
    from loceval.evaluation import EvaluationResult
    from loceval.metrics.pose_errors import ErrorSeries
    from loceval.metrics.relations import PoseRelation
    from loceval.trajectory import Trajectory

__all__ = ["EvoRun"]


@dataclass(frozen=True, slots=True, eq=False)
class EvoRun:
    """One ``loceval ape`` or ``rpe`` run: what evo's result zip and the printout hold.

    Attributes:
        metric: ``ape`` or ``rpe``.
        title: evo's title line (``APE w.r.t. translation part (m)``).
        alignment_words: evo's alignment line (``(with SE(3) Umeyama alignment)``), or "".
        series: the errors, stamped with the (first) matched reference pose.
        relation: the pose relation.
        result: loceval's evaluation (matching, alignment, intervals, notes).
        ref_name: the reference's name (its file or topic, as evo names it).
        est_name: the estimate's name.
        reference: the reference's matched poses.
        estimate: the estimate's matched poses after the alignment.
        info: evo's ``info`` entries (label, title, relation, delta).
        pairs: RPE: the ``(i, j)`` index pairs into the matched poses; APE: None.
        estimate_poses: how many poses the estimate has (in the time window).
    """

    metric: str
    title: str
    alignment_words: str
    series: ErrorSeries
    relation: PoseRelation
    result: EvaluationResult
    ref_name: str
    est_name: str
    reference: Trajectory
    estimate: Trajectory
    info: dict[str, object]
    pairs: tuple[IntArray, IntArray] | None = None
    estimate_poses: int = 0

    @property
    def pairs_second(self) -> IntArray:
        """Return the index of each error's pose (RPE: the pair's second pose)."""
        if self.pairs is None:
            return np.arange(len(self.series))
        return self.pairs[1]
