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
from loceval.results.trials import (
    BaselineDifferenceRead,
    BaselineRead,
    FailedTrialRead,
    IntervalRead,
    SystemComparisonRead,
    SystemRead,
    TrialMetricRead,
    objects,
)

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


def _pair(value: object) -> tuple[float, float] | None:
    """A written ``[low, high]`` of two finite numbers, else None."""
    if not isinstance(value, Sequence) or isinstance(value, str | bytes) or len(value) != 2:
        return None
    low, high = _finite(value[0]), _finite(value[1])
    return None if low is None or high is None else (low, high)


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
        systems=tuple(SystemRead.read(s) for s in objects(found.get("systems"))),
        system_comparisons=tuple(
            SystemComparisonRead.read(c) for c in objects(found.get("system_comparisons"))
        ),
        baseline=BaselineRead.read(found.get("baseline")),
    )
