"""The result document's trials, system comparisons and baseline, read back typed.

Part of the reader of :mod:`loceval.results.document` (which re-exports these types): the
``systems`` of trials (:mod:`loceval.assessment.trials` writes them), the
``system_comparisons`` and the ``baseline`` object (:mod:`loceval.assessment.baseline`).
A document from before them has none.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal

from loceval.errors import InputError

__all__ = [
    "BaselineDifferenceRead",
    "BaselineRead",
    "FailedTrialRead",
    "IntervalRead",
    "SystemComparisonRead",
    "SystemRead",
    "TrialMetricRead",
    "objects",
]


def _finite(value: object) -> float | None:
    """A finite number as float, else None."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _mapping(value: object) -> Mapping[str, Any] | None:
    return value if isinstance(value, Mapping) else None


def _texts(value: object) -> tuple[str, ...]:
    if not isinstance(value, Sequence) or isinstance(value, str | bytes):
        return ()
    return tuple(str(v) for v in value)


def _text(value: object) -> str | None:
    return value if isinstance(value, str) else None


def _pair(value: object) -> tuple[float, float] | None:
    if not isinstance(value, Sequence) or isinstance(value, str | bytes) or len(value) != 2:
        return None
    lo, hi = _finite(value[0]), _finite(value[1])
    return None if lo is None or hi is None else (lo, hi)


def objects(value: object) -> list[Mapping[str, Any]]:
    """The objects of a JSON list (others skipped); [] when it is no list."""
    if not isinstance(value, Sequence) or isinstance(value, str | bytes):
        return []
    return [m for v in value if (m := _mapping(v)) is not None]


@dataclass(frozen=True, slots=True)
class IntervalRead:
    """An interval over trials: ``low``, ``high``, its ``level`` and ``method``."""

    low: float
    high: float
    level: float | None
    method: str

    @classmethod
    def read(cls, block: object) -> IntervalRead | None:
        """Read an interval block; None when absent (too few trials)."""
        found = _mapping(block)
        if found is None:
            return None
        low, high = _finite(found.get("low")), _finite(found.get("high"))
        if low is None or high is None:
            return None
        return cls(low, high, _finite(found.get("level")), _text(found.get("method")) or "")


@dataclass(frozen=True, slots=True)
class TrialMetricRead:
    """One metric of a system over its trials (:class:`loceval.assessment.trials.MetricOverTrials`).

    Attributes:
        metric: the key (``ate_rmse``, ``rpe_rmse``, ``ate_rot_rmse``, ``rpe_rot_rmse``).
        unit: the unit.
        values: the value of each trial, in trial order.
        figures: ``median``, ``mean``, ``std``, ``min``, ``max``, ``q1``, ``q3``, ``iqr``.
        interval: the 95 % t-interval of the mean (None: fewer than 3 trials).
        median_interval: the order-statistic interval of the median (None: fewer than 6).
        note: why an interval is missing, or None.
    """

    metric: str
    unit: str
    values: tuple[float, ...]
    figures: Mapping[str, float]
    interval: IntervalRead | None
    median_interval: IntervalRead | None
    note: str | None

    @property
    def n(self) -> int:
        """The number of trials summarised."""
        return len(self.values)

    def figure(self, name: str) -> float | None:
        """A figure (``median``, ``mean``, ...), or None."""
        return self.figures.get(name)

    @classmethod
    def read(cls, metric: str, block: Mapping[str, Any]) -> TrialMetricRead:
        """Read a metric block of a system."""
        raw = block.get("values")
        values = tuple(
            v
            for v in (_finite(x) for x in (raw if isinstance(raw, Sequence) else ()))
            if v is not None
        )
        figures = {
            k: v
            for k in ("median", "mean", "std", "min", "max", "q1", "q3", "iqr")
            if (v := _finite(block.get(k))) is not None
        }
        return cls(
            metric=metric,
            unit=_text(block.get("unit")) or "",
            values=values,
            figures=figures,
            interval=IntervalRead.read(block.get("interval")),
            median_interval=IntervalRead.read(block.get("median_interval")),
            note=_text(block.get("note")),
        )


@dataclass(frozen=True, slots=True)
class FailedTrialRead:
    """A failed trial: its ``name``, a ``code`` and the ``reason`` in a sentence."""

    name: str
    code: str
    reason: str


@dataclass(frozen=True, slots=True)
class SystemRead:
    """A system of trials.

    Attributes:
        name: the system's name.
        trials: the trials that entered its figures, in order.
        failed: the trials that failed (counted, named, with why).
        metrics: each metric over the trials, by key.
    """

    name: str
    trials: tuple[str, ...]
    failed: tuple[FailedTrialRead, ...]
    metrics: Mapping[str, TrialMetricRead]

    @classmethod
    def read(cls, block: Mapping[str, Any]) -> SystemRead:
        """Read one item of ``systems``."""
        metrics = _mapping(block.get("metrics")) or {}
        return cls(
            name=_text(block.get("name")) or "",
            trials=_texts(block.get("trials")),
            failed=tuple(
                FailedTrialRead(
                    _text(f.get("name")) or "",
                    _text(f.get("code")) or "",
                    _text(f.get("reason")) or "",
                )
                for f in objects(block.get("failed"))
            ),
            metrics={
                str(k): TrialMetricRead.read(str(k), m)
                for k, v in metrics.items()
                if (m := _mapping(v)) is not None
            },
        )


@dataclass(frozen=True, slots=True)
class SystemComparisonRead:
    """Two systems compared over their trials (:class:`loceval.assessment.trials.SystemComparison`).

    Attributes:
        a: system A.
        b: system B.
        metric: the metric's key.
        unit: its unit.
        difference: the Hodges-Lehmann shift A - B.
        interval: its interval, or None (too few trials).
        confidence: the interval's exact coverage, or None.
        p_value: the two-sided Mann-Whitney p-value.
        verdict: ``a_better``, ``b_better``, ``within_noise`` or ``too_few_trials``.
        summary: one sentence.
    """

    a: str
    b: str
    metric: str
    unit: str
    difference: float | None
    interval: tuple[float, float] | None
    confidence: float | None
    p_value: float | None
    verdict: str
    summary: str

    @classmethod
    def read(cls, block: Mapping[str, Any]) -> SystemComparisonRead:
        """Read one item of ``system_comparisons``."""
        return cls(
            a=_text(block.get("a")) or "",
            b=_text(block.get("b")) or "",
            metric=_text(block.get("metric")) or "",
            unit=_text(block.get("unit")) or "",
            difference=_finite(block.get("difference")),
            interval=_pair(block.get("interval")),
            confidence=_finite(block.get("confidence")),
            p_value=_finite(block.get("p_value")),
            verdict=_text(block.get("verdict")) or "",
            summary=_text(block.get("summary")) or "",
        )


BaselineVerdict = Literal["better", "worse", "within_noise", "undetermined"]
_BASELINE_VERDICTS: Final[Mapping[object, BaselineVerdict]] = {
    v: v for v in ("better", "worse", "within_noise", "undetermined")
}


@dataclass(frozen=True, slots=True)
class BaselineDifferenceRead:
    """One figure against the baseline's (:class:`loceval.assessment.baseline.BaselineDifference`).

    Attributes:
        name: the estimate's or system's name.
        level: ``estimate`` or ``system``.
        metric: ``ate_rmse`` or ``rpe_rmse``.
        unit: the unit.
        current: the figure now.
        baseline: the baseline's figure.
        difference: now minus baseline (negative: better now).
        interval: its 95 % interval, or None.
        paired: whether the interval is paired.
        verdict: ``better``, ``worse``, ``within_noise`` or ``undetermined``.
        method: how the interval is made.
        summary: one sentence.
    """

    name: str
    level: str
    metric: str
    unit: str
    current: float | None
    baseline: float | None
    difference: float | None
    interval: tuple[float, float] | None
    paired: bool
    verdict: BaselineVerdict
    method: str
    summary: str

    @classmethod
    def read(cls, k: int, block: Mapping[str, Any]) -> BaselineDifferenceRead:
        """Read ``baseline.comparisons[k]``.

        Raises:
            InputError: its verdict is none of the four.
        """
        verdict = _BASELINE_VERDICTS.get(block.get("verdict"))
        if verdict is None:
            msg = (
                f"baseline.comparisons[{k}] of the result document has no verdict (better, "
                "worse, within_noise or undetermined)."
            )
            raise InputError(msg)
        return cls(
            name=_text(block.get("name")) or "",
            level=_text(block.get("level")) or "estimate",
            metric=_text(block.get("metric")) or "",
            unit=_text(block.get("unit")) or "",
            current=_finite(block.get("current")),
            baseline=_finite(block.get("baseline")),
            difference=_finite(block.get("difference")),
            interval=_pair(block.get("interval")),
            paired=block.get("paired") is True,
            verdict=verdict,
            method=_text(block.get("method")) or "",
            summary=_text(block.get("summary")) or "",
        )


@dataclass(frozen=True, slots=True)
class BaselineRead:
    """The ``baseline`` object: what was compared with, each difference, and notes."""

    label: str
    kind: str
    source: str
    comparisons: tuple[BaselineDifferenceRead, ...]
    notes: tuple[str, ...]

    @classmethod
    def read(cls, block: object) -> BaselineRead | None:
        """Read the ``baseline`` object; None without one."""
        found = _mapping(block)
        if found is None:
            return None
        return cls(
            label=_text(found.get("label")) or "",
            kind=_text(found.get("kind")) or "",
            source=_text(found.get("source")) or "",
            comparisons=tuple(
                BaselineDifferenceRead.read(k, c)
                for k, c in enumerate(objects(found.get("comparisons")))
            ),
            notes=_texts(found.get("notes")),
        )
