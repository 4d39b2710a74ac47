"""The tolerance verdict: pass, fail or undecided, and where on the path the errors exceed it."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from loceval.assessment.uncertainty import check_tolerance
from loceval.core.arrays import BoolArray
from loceval.core.norms import row_norms
from loceval.errors import InputError
from loceval.metrics.pose_errors import ErrorSeries, share_within
from loceval.trajectory import Trajectory

if TYPE_CHECKING:
    from loceval.assessment.uncertainty import ToleranceVerdict

__all__ = ["FailingSpan", "Tolerance", "Verdict", "failing_spans", "tolerance_verdict_of"]

_NS_PER_S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class Tolerance:
    """An application tolerance: ``share`` of the poses within ``distance_m``.

    ``Tolerance(0.10, 0.95)`` reads "95 % of poses within 0.10 m" (CLI ``0.10@95``).
    """

    distance_m: float
    share: float

    def __post_init__(self) -> None:
        """Check the values (:func:`~loceval.assessment.uncertainty.check_tolerance`)."""
        check_tolerance(self.distance_m, self.share)

    @classmethod
    def parse(cls, text: str) -> Tolerance:
        """Parse ``"0.10@95"`` (metres @ percent); a bare ``"0.10"`` means 95 %.

        Raises:
            InputError: the text has another form.
        """
        match = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(?:m)?\s*(?:@\s*([0-9.eE+-]+)\s*%?)?\s*", text)
        try:
            if match is None:
                raise ValueError(text)  # noqa: TRY301  (one message for every bad form)
            distance = float(match.group(1))
            share = float(match.group(2)) / 100.0 if match.group(2) else 0.95
        except ValueError:
            msg = (
                f"The tolerance takes METRES@PERCENT like 0.10@95 (95 % of poses within "
                f"0.10 m), got {text!r}."
            )
            raise InputError(msg, option="tolerance") from None
        return cls(distance, share)

    def __str__(self) -> str:
        """Return the words a non-expert reads."""
        return f"{self.share * 100:g} % of poses within {self.distance_m:g} m"


@dataclass(frozen=True, slots=True)
class FailingSpan:
    """A stretch beyond the tolerance: consecutive matched poses whose error exceeds it.

    A stretch ends where the error comes back within the tolerance or where the path
    breaks (a tracking loss of the reference or of the estimate: what happened in between
    was not measured). Times are seconds since the reference's first pose; indices count
    the matched poses (``errors.csv``'s rows of the estimate).

    Attributes:
        start_s: the first pose beyond the tolerance.
        end_s: the last one.
        poses: how many poses it holds.
        max_error_m: its worst error, metres.
        max_error_position_xyz: the ground truth's position at the worst error, metres.
        length_m: the distance the device travelled from its first to its last pose
            (along the ground truth), metres.
        first_index: the matched pose it starts at.
        last_index: the matched pose it ends at (inclusive).
        max_error_index: the matched pose of its worst error.
        max_error_s: the time of its worst error.
        space: the building's space (room) it lies in, when the building model names its
            spaces: the one holding most of its poses (:mod:`loceval.assessment.spaces`).
    """

    start_s: float
    end_s: float
    poses: int
    max_error_m: float
    max_error_position_xyz: tuple[float, float, float]
    length_m: float = 0.0
    first_index: int = 0
    last_index: int = 0
    max_error_index: int = 0
    max_error_s: float = 0.0
    space: str | None = None

    @property
    def duration_s(self) -> float:
        """Return the time from its first to its last pose, seconds."""
        return self.end_s - self.start_s

    def words(self, tolerance_m: float) -> str:
        """Return the stretch as a site engineer says it: "beyond 0.025 m for 4.1 s in 2.14 Office".

        Durations read to a tenth of a second (:mod:`loceval.core.lengths`).
        """
        where = "" if self.space is None else f" in {self.space}"
        return f"beyond {tolerance_m:g} m for {self.duration_s:.1f} s{where}"

    def to_dict(self) -> dict[str, object]:
        """Return the JSON form."""
        return {
            "start_s": self.start_s,
            "end_s": self.end_s,
            "duration_s": self.duration_s,
            "poses": self.poses,
            "length_m": self.length_m,
            "max_error_m": self.max_error_m,
            "max_error_s": self.max_error_s,
            "max_error_position": list(self.max_error_position_xyz),
            "first_index": self.first_index,
            "last_index": self.last_index,
            "max_error_index": self.max_error_index,
            "space": self.space,
        }


def failing_spans(
    ate: ErrorSeries,
    reference: Trajectory,
    tolerance_m: float,
    t0_ns: int,
    *,
    breaks: BoolArray | None = None,
) -> tuple[FailingSpan, ...]:
    """Return the stretches whose error exceeds ``tolerance_m``, the worst first.

    Vectorised over poses: the stretches are the runs of ``error > tolerance_m`` cut at
    ``breaks``; their lengths come from one cumulative sum of the ground truth's steps and
    their worst errors from one ``maximum.reduceat``.

    Args:
        ate: ATE translation errors, metres, in time order.
        reference: the reference at the errors' stamps (the device's true positions).
        tolerance_m: the tolerance's distance, metres.
        t0_ns: the stamp times count from (the reference's first pose).
        breaks: (N - 1,) True after each pose where the path breaks (a tracking loss,
            :func:`loceval.core.gaps.path_breaks`); no break by default.

    Returns:
        The stretches, sorted by their worst error (largest first), ties by time.
    """
    values = ate.values
    n = len(values)
    over: BoolArray = values > tolerance_m
    if not over.any():
        return ()
    flags = over.astype(np.int8)
    # a run starts where "over" rises or a break lies just before an over pose
    rises = np.diff(np.concatenate(([0], flags))) == 1
    cut = np.zeros(n, dtype=bool)
    if breaks is not None and n > 1:
        cut[1:] = np.asarray(breaks, dtype=bool) & over[1:] & over[:-1]
    starts = np.flatnonzero(rises | cut)
    # each run ends before the next start or where "over" falls
    run_id = np.cumsum(rises | cut) - 1
    idx = np.flatnonzero(over)
    ends = np.zeros(len(starts), dtype=np.intp)
    np.maximum.at(ends, run_id[idx], idx)  # the last over pose of each run (inclusive)
    worst = np.maximum.reduceat(values, starts)  # the worst value in [start, next start)
    # the worst pose of each run: the first pose of the run with that value
    run_worst = np.full(n, np.inf)
    run_worst[starts[0] :] = np.repeat(worst, np.diff(np.append(starts, n)))
    is_worst = over & (values == run_worst)
    first_worst = np.full(len(starts), n, dtype=np.intp)
    hit = np.flatnonzero(is_worst)
    np.minimum.at(first_worst, run_id[hit], hit)
    steps = row_norms(np.diff(reference.positions_xyz, axis=0))
    travelled = np.concatenate(([0.0], np.cumsum(steps)))  # no stretch crosses a break
    order = np.lexsort((starts, -worst))  # the worst first, ties by time
    a, b, w = starts[order], ends[order], first_worst[order]
    seconds = (ate.stamps_ns - t0_ns) / _NS_PER_S
    # every field gathered at once; the loop only builds one record per stretch
    columns = zip(
        seconds[a].tolist(),
        seconds[b].tolist(),
        (b - a + 1).tolist(),
        values[w].tolist(),
        reference.positions_xyz[w].tolist(),
        (travelled[b] - travelled[a]).tolist(),
        a.tolist(),
        b.tolist(),
        w.tolist(),
        seconds[w].tolist(),
        strict=True,
    )
    out = [
        FailingSpan(
            start_s=start,
            end_s=end,
            poses=poses,
            max_error_m=max_error,
            max_error_position_xyz=(pos[0], pos[1], pos[2]),
            length_m=length,
            first_index=first,
            last_index=last,
            max_error_index=at,
            max_error_s=at_s,
        )
        for start, end, poses, max_error, pos, length, first, last, at, at_s in columns
    ]
    return tuple(out)


@dataclass(frozen=True, slots=True)
class Verdict:
    """Pass, fail or undecided against a tolerance, and where on the path it fails.

    With the share's 95 % interval (``share_ci95``) the verdict is PASS when the whole
    interval reaches the required share, FAIL when it falls short, and undecided when it
    straddles the requirement; ``passed`` is true only for PASS (an undecided run has not
    shown that the system meets the tolerance). Without the interval (intervals turned
    off) the measured share decides.
    """

    tolerance: Tolerance
    share_within: float
    passed: bool
    failing_spans: tuple[FailingSpan, ...]
    share_ci95: tuple[float, float] | None = None
    outcome: str = ""
    """``pass``, ``fail`` or ``undecided``; empty: from ``passed``."""

    @property
    def result(self) -> str:
        """Return ``pass``, ``fail`` or ``undecided``."""
        return self.outcome or ("pass" if self.passed else "fail")

    @property
    def summary(self) -> str:
        """One sentence for a non-expert."""
        interval = ""
        if self.share_ci95 is not None:
            lo, hi = self.share_ci95
            interval = f", 95 % interval {lo * 100:.1f}-{hi * 100:.1f} %"
        text = (
            f"{self.result.upper()}: {self.share_within * 100:.1f} % of poses are within "
            f"{self.tolerance.distance_m:g} m (required: {self.tolerance.share * 100:g} %"
            f"{interval})."
        )
        if self.result == "undecided":
            text = (
                f"{text[:-1]}; the interval straddles the requirement, so this run cannot "
                "tell whether the system meets it: record a longer run."
            )
        return text

    def to_dict(self) -> dict[str, object]:
        """Return the JSON form."""
        return {
            "tolerance_m": self.tolerance.distance_m,
            "required_share": self.tolerance.share,
            "share_within": self.share_within,
            "passed": self.passed,
            "outcome": self.result,
            "ci95": None if self.share_ci95 is None else list(self.share_ci95),
            "summary": self.summary,
            "failing_spans": [s.to_dict() for s in self.failing_spans],
        }


def tolerance_verdict_of(
    ate: ErrorSeries,
    reference: Trajectory,
    tolerance: Tolerance,
    t0_ns: int,
    judged: ToleranceVerdict | None,
    *,
    breaks: BoolArray | None = None,
) -> Verdict:
    """Return the verdict of the ATE against ``tolerance`` and the stretches that exceed it.

    Args:
        ate: ATE translation errors, metres, in time order.
        reference: the reference at the errors' stamps.
        tolerance: the tolerance.
        t0_ns: the stamp times count from (the reference's first pose).
        judged: the share's interval verdict, if intervals were computed.
        breaks: (N - 1,) where the path breaks (tracking loss): a stretch ends there.
    """
    share = share_within(ate, [tolerance.distance_m])[tolerance.distance_m]
    spans = failing_spans(ate, reference, tolerance.distance_m, t0_ns, breaks=breaks)
    outcome = "" if judged is None else judged.outcome.value
    return Verdict(
        tolerance=tolerance,
        share_within=share,
        passed=share >= tolerance.share if judged is None else outcome == "pass",
        failing_spans=spans,
        share_ci95=None if judged is None else judged.ci95,
        outcome=outcome,
    )
