"""The result document (``result.json``) read back through typed views.

The pipelines write the document: :meth:`loceval.evaluation.EvaluationResult.to_dict` (a
trajectory or ranging evaluation) and
:meth:`loceval.checkpoint_evaluation.CheckpointEvaluation.to_dict` (control points).
Everything that reads one back (the service's job summaries, comparisons and Hops, the
summary report) reads it here, once: each statistics block by the fields of
:class:`~loceval.metrics.pose_errors.ErrorStats`, the type the pipeline writes it from, the
verdict by its outcome as :class:`~loceval.assessment.verdict.Verdict` writes it, and the
warnings of the reference and of each estimate. No caller digs in the dict: a key the
writers rename reads as missing here, and the round trip of every kind of document
(``tests/loceval/results``) fails instead of a figure quietly becoming None.

Trials and the baseline (issue 41) are read here too: ``estimates[k].system``, the
``systems`` (:class:`SystemRead`: trials, failed trials, each metric over the trials with
its intervals), the ``system_comparisons`` and the ``baseline`` object
(:class:`BaselineRead`: each difference with its verdict). Their fields are described in
:mod:`loceval.assessment.trials` and :mod:`loceval.assessment.baseline`; a document from
before them reads as no systems, no comparisons and no baseline.

A document may lack what its kind or its age leaves out (a control-point estimate has no
RPE; documents from before the intervals carry no ``ci95`` and a verdict without
``outcome``): those read as None. What is not a result document at all (no list of
estimates, an estimate that is not an object) raises :class:`InputError`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, Final, Literal

from loceval.errors import InputError
from loceval.metrics.pose_errors import ErrorStats

__all__ = [
    "STAT_NAMES",
    "BaselineDifferenceRead",
    "BaselineRead",
    "EstimateRead",
    "FailedTrialRead",
    "IntervalRead",
    "ResultRead",
    "StatsBlock",
    "SystemComparisonRead",
    "SystemRead",
    "TrialMetricRead",
    "VerdictRead",
    "read_result",
]

STAT_NAMES: Final = tuple(f.name for f in fields(ErrorStats))
"""The statistics of a block, in the order the pipeline writes them (``rmse`` ... ``n``)."""

Outcome = Literal["pass", "fail", "undecided"]
_OUTCOMES: Final[Mapping[object, Outcome]] = {
    "pass": "pass",
    "fail": "fail",
    "undecided": "undecided",
}
_SECTIONS: Final = ("map", "ranging")
"""The document's parts besides the reference and the estimates that carry warnings."""


def _finite(value: object) -> float | None:
    """A finite number as float, else None (JSON's null, NaN written as null, text)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _count(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _mapping(value: object) -> Mapping[str, Any] | None:
    return value if isinstance(value, Mapping) else None


@dataclass(frozen=True, slots=True)
class StatsBlock:
    """One statistics block: an error series' :class:`ErrorStats`, and its 95 % intervals.

    Attributes:
        values: the block's finite statistics by :class:`ErrorStats` field (``n`` as int).
        ci95: the 95 % interval of each statistic, as written (None: not computed).
        n_effective: the series' effective sample size (None: not computed).
        document: the block as written (for a caller that passes it on whole).
    """

    values: Mapping[str, float]
    ci95: Mapping[str, Any] | None
    n_effective: float | None
    document: Mapping[str, Any]

    @classmethod
    def read(cls, block: object) -> StatsBlock | None:
        """Read a block; None when it is absent (a position-only rotation, no RPE)."""
        found = _mapping(block)
        if found is None:
            return None
        values: dict[str, float] = {}
        for name in STAT_NAMES:
            number = _count(found.get(name)) if name == "n" else _finite(found.get(name))
            if number is not None:
                values[name] = number
        return cls(values, _mapping(found.get("ci95")), _finite(found.get("n_effective")), found)

    def value(self, name: str) -> float | None:
        """The statistic ``name`` (an :class:`ErrorStats` field), or None when absent."""
        return self.values.get(name)

    @property
    def rmse(self) -> float | None:
        """The root mean square error, or None."""
        return self.values.get("rmse")

    @property
    def n(self) -> int | None:
        """How many errors the statistics summarise, or None."""
        n = self.values.get("n")
        return None if n is None else int(n)

    def stats(self) -> ErrorStats | None:
        """Return the block as the pipeline's :class:`ErrorStats`, or None when incomplete."""
        if any(name not in self.values for name in STAT_NAMES):
            return None
        return ErrorStats(**{name: self.values[name] for name in STAT_NAMES})  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True)
class VerdictRead:
    """The tolerance verdict of an estimate.

    Attributes:
        passed: whether the estimate meets the tolerance (False when undecided).
        outcome: ``pass``, ``fail`` or ``undecided`` (documents before the intervals carry
            only ``passed``: pass or fail).
        share_within: the share of poses within the tolerance's distance, 0-1 (None: not
            written).
        tolerance_m: the tolerance's distance, metres (None: not written).
        required_share: the share the tolerance requires, 0-1 (None: not written).
        ci95: the 95 % interval of ``share_within`` (None: intervals off or not written).
    """

    passed: bool
    outcome: Outcome
    share_within: float | None = None
    tolerance_m: float | None = None
    required_share: float | None = None
    ci95: tuple[float, float] | None = None

    @classmethod
    def read(cls, verdict: object, where: str = "verdict") -> VerdictRead | None:
        """Read a verdict; None without one (no tolerance given).

        Raises:
            InputError: a verdict with its interval (``ci95``) but no outcome.
        """
        found = _mapping(verdict)
        passed = None if found is None else found.get("passed")
        if found is None or not isinstance(passed, bool):
            return None
        written = found.get("outcome")
        known = _OUTCOMES.get(written) if isinstance(written, str) else None
        if known is None and "ci95" in found:  # written since the intervals: always there
            msg = f"{where} of the result document has no outcome (pass, fail or undecided)."
            raise InputError(msg)
        # before the intervals (no outcome written): the outcome from passed
        outcome = known or ("pass" if passed else "fail")
        return cls(
            passed,
            outcome,
            share_within=_finite(found.get("share_within")),
            tolerance_m=_finite(found.get("tolerance_m")),
            required_share=_finite(found.get("required_share")),
            ci95=_pair(found.get("ci95")),
        )


@dataclass(frozen=True, slots=True)
class EstimateRead:
    """One estimate of a result document.

    Attributes:
        index: its place among the estimates (0-based).
        name: its name as written (None or empty when it has none).
        matched: poses matched to the reference (control points: visits scored).
        ate_translation: ATE of the translation, metres.
        ate_rotation: ATE of the rotation, degrees (None: position-only).
        rpe_translation: RPE of the translation, metres (None: control points).
        rpe_rotation: RPE of the rotation, degrees.
        verdict: the tolerance verdict (None: no tolerance).
        warnings: what the pipeline warned of for this estimate.
        document: the estimate as written (for blocks a caller passes on whole).
        system: the system it is a trial of (None: not a trial).
    """

    index: int
    name: str | None
    matched: int | None
    ate_translation: StatsBlock | None
    ate_rotation: StatsBlock | None
    rpe_translation: StatsBlock | None
    rpe_rotation: StatsBlock | None
    verdict: VerdictRead | None
    warnings: tuple[str, ...]
    document: Mapping[str, Any]
    system: str | None = None

    @property
    def label(self) -> str:
        """Its name, or ``estimate k`` (1-based) when it has none."""
        return self.name if self.name and self.name.strip() else f"estimate {self.index + 1}"

    def block(self, metric: Literal["ate", "rpe"]) -> StatsBlock | None:
        """The translation block of ``ate`` or ``rpe``."""
        return self.ate_translation if metric == "ate" else self.rpe_translation

    def rmse_m(self, metric: Literal["ate", "rpe"]) -> float | None:
        """The RMSE of the translation error of ``ate`` or ``rpe``, metres, or None."""
        block = self.block(metric)
        return None if block is None else block.rmse

    def figures_as_written(self) -> dict[str, Any]:
        """The ATE, RPE and verdict objects as written (None where it has none).

        For a caller that passes them on whole (Hops' statistics), as ``{"ate", "rpe",
        "verdict"}``.
        """
        return {key: self.document.get(key) for key in ("ate", "rpe", "verdict")}

    @classmethod
    def read(cls, index: int, estimate: object) -> EstimateRead:
        """Read ``estimates[index]``.

        Raises:
            InputError: it is not an object.
        """
        found = _mapping(estimate)
        if found is None:
            msg = f"estimates[{index}] of the result document is not an object."
            raise InputError(msg)
        ate = _mapping(found.get("ate")) or {}
        rpe = _mapping(found.get("rpe")) or {}
        name = found.get("name")
        return cls(
            index=index,
            name=name if isinstance(name, str) else None,
            matched=_count(found.get("matched")),
            ate_translation=StatsBlock.read(ate.get("translation_m")),
            ate_rotation=StatsBlock.read(ate.get("rotation_deg")),
            rpe_translation=StatsBlock.read(rpe.get("translation_m")),
            rpe_rotation=StatsBlock.read(rpe.get("rotation_deg")),
            verdict=VerdictRead.read(found.get("verdict"), f"estimates[{index}].verdict"),
            warnings=_texts(found.get("warnings")),
            document=found,
            system=_text(found.get("system")),
        )


def _text(value: object) -> str | None:
    return value if isinstance(value, str) else None


def _pair(value: object) -> tuple[float, float] | None:
    if not isinstance(value, Sequence) or isinstance(value, str | bytes) or len(value) != 2:
        return None
    lo, hi = _finite(value[0]), _finite(value[1])
    return None if lo is None or hi is None else (lo, hi)


def _objects(value: object) -> list[Mapping[str, Any]]:
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
                for f in _objects(block.get("failed"))
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
                for k, c in enumerate(_objects(found.get("comparisons")))
            ),
            notes=_texts(found.get("notes")),
        )


def _texts(value: object) -> tuple[str, ...]:
    if not isinstance(value, Sequence) or isinstance(value, str | bytes):
        return ()
    return tuple(str(v) for v in value)


@dataclass(frozen=True, slots=True)
class ResultRead:
    """A result document, read.

    Attributes:
        kind: ``trajectory`` (and ranging) or ``control_points``, by its reference.
        reference_name: the reference's name, as written.
        reference_duration_s: the reference's duration (None: control points).
        reference_warnings: what the pipeline warned of for the reference.
        estimates: the estimates, in their order.
        section_warnings: the warnings of the document's other parts, by part (``map``,
            ``ranging``), when it has them.
        document: the document as written.
        systems: the systems of trials (empty: no estimate named a system).
        system_comparisons: every two systems compared over their trials.
        baseline: the comparison with a baseline (None: no baseline given).
    """

    kind: Literal["trajectory", "control_points"]
    reference_name: str | None
    reference_duration_s: float | None
    reference_warnings: tuple[str, ...]
    estimates: tuple[EstimateRead, ...]
    section_warnings: Mapping[str, tuple[str, ...]]
    document: Mapping[str, Any]
    systems: tuple[SystemRead, ...] = ()
    system_comparisons: tuple[SystemComparisonRead, ...] = ()
    baseline: BaselineRead | None = None

    @property
    def failed_trials(self) -> tuple[tuple[str, FailedTrialRead], ...]:
        """Every failed trial as ``(system, trial)``, system by system."""
        return tuple((s.name, f) for s in self.systems for f in s.failed)

    def warnings(self) -> list[tuple[str, str]]:
        """Every warning of the document as ``(where, text)``, in the document's order.

        ``where`` is ``reference``, an estimate's label (:attr:`EstimateRead.label`), ``map``
        or ``ranging``.
        """
        found = [("reference", w) for w in self.reference_warnings]
        found += [(where, w) for where, texts in self.section_warnings.items() for w in texts]
        found += [(e.label, w) for e in self.estimates for w in e.warnings]
        return found


def read_result(document: object) -> ResultRead:
    """Read a result document (``result.json``, or an evaluation's stored result).

    Raises:
        InputError: it has no list of estimates, or an estimate is not an object.
    """
    found = _mapping(document)
    estimates = None if found is None else found.get("estimates")
    if found is None or not isinstance(estimates, Sequence) or isinstance(estimates, str | bytes):
        msg = "The result document has no 'estimates' list; is it a result.json?"
        raise InputError(msg)
    reference = _mapping(found.get("reference")) or {}
    name = reference.get("name")
    return ResultRead(
        kind="control_points" if reference.get("kind") == "control_points" else "trajectory",
        reference_name=name if isinstance(name, str) else None,
        reference_duration_s=_finite(reference.get("duration_s")),
        reference_warnings=_texts(reference.get("warnings")),
        estimates=tuple(EstimateRead.read(k, e) for k, e in enumerate(estimates)),
        section_warnings={
            part: _texts(section.get("warnings"))
            for part in _SECTIONS
            if (section := _mapping(found.get(part))) is not None
        },
        document=found,
        systems=tuple(SystemRead.read(s) for s in _objects(found.get("systems"))),
        system_comparisons=tuple(
            SystemComparisonRead.read(c) for c in _objects(found.get("system_comparisons"))
        ),
        baseline=BaselineRead.read(found.get("baseline")),
    )
