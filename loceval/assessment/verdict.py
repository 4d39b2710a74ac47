"""The tolerance verdict: pass, fail or undecided, and where on the path the errors exceed it."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from loceval.assessment.uncertainty import check_tolerance
from loceval.core.arrays import BoolArray
from loceval.errors import InputError
from loceval.metrics.pose_errors import ErrorSeries, share_within
from loceval.trajectory import Trajectory

if TYPE_CHECKING:
    from loceval.assessment.uncertainty import ToleranceVerdict

__all__ = ["FailingSpan", "Tolerance", "Verdict", "tolerance_verdict_of"]

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
    """A stretch of consecutive matched poses whose error exceeds the tolerance.

    Times are seconds since the reference's first pose.
    """

    start_s: float
    end_s: float
    poses: int
    max_error_m: float
    max_error_position_xyz: tuple[float, float, float]

    def to_dict(self) -> dict[str, object]:
        """Return the JSON form."""
        return {
            "start_s": self.start_s,
            "end_s": self.end_s,
            "poses": self.poses,
            "max_error_m": self.max_error_m,
            "max_error_position": list(self.max_error_position_xyz),
        }


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
) -> Verdict:
    """Return the verdict of the ATE against ``tolerance`` and the stretches that exceed it.

    Args:
        ate: ATE translation errors, metres, in time order.
        reference: the reference at the errors' stamps.
        tolerance: the tolerance.
        t0_ns: the stamp times count from (the reference's first pose).
        judged: the share's interval verdict, if intervals were computed.
    """
    share = share_within(ate, [tolerance.distance_m])[tolerance.distance_m]
    over: BoolArray = ate.values > tolerance.distance_m
    spans = []
    if over.any():
        edges = np.diff(np.concatenate(([0], over.astype(np.int8), [0])))
        starts = np.flatnonzero(edges == 1)
        ends = np.flatnonzero(edges == -1)  # exclusive
        for a, b in zip(starts, ends, strict=True):  # one iteration per failing stretch
            k = a + int(np.argmax(ate.values[a:b]))
            pos = reference.positions_xyz[k]
            spans.append(
                FailingSpan(
                    start_s=(int(ate.stamps_ns[a]) - t0_ns) / _NS_PER_S,
                    end_s=(int(ate.stamps_ns[b - 1]) - t0_ns) / _NS_PER_S,
                    poses=int(b - a),
                    max_error_m=float(ate.values[k]),
                    max_error_position_xyz=(float(pos[0]), float(pos[1]), float(pos[2])),
                )
            )
    spans.sort(key=lambda s: s.max_error_m, reverse=True)
    outcome = "" if judged is None else judged.outcome.value
    return Verdict(
        tolerance=tolerance,
        share_within=share,
        passed=share >= tolerance.share if judged is None else outcome == "pass",
        failing_spans=tuple(spans),
        share_ci95=None if judged is None else judged.ci95,
        outcome=outcome,
    )
