"""The gate a CI job reads: did any estimate fail, stay undecided, or get worse?

``--fail-on fail,undecided,worse`` (the API: ``options.fail_on``) names the conditions that
close the gate; :func:`judge_gate` reads them off a result document
(:class:`~loceval.results.document.ResultRead`), so the command line (from the result it has
just computed) and the service (from the stored document) judge the same way:

- ``fail``: an estimate's tolerance verdict is ``fail`` (its share's interval falls short);
- ``undecided``: a verdict is ``undecided`` (the interval straddles the requirement);
- ``worse``: a comparison with the baseline says ``worse`` (an estimate's own, or a
  system's over all its trials: :func:`gated_comparisons`).

The gate is closed when one of them holds; its reasons say which estimate, and the figures
that decided it, in one sentence each. Conditions that need a tolerance or a baseline
refuse to run without one (:func:`check_fail_on`): a gate that cannot close would let every
merge request through.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final

from loceval.assessment.baseline import BASELINE_METRICS
from loceval.core.lengths import length_unit
from loceval.errors import InputError
from loceval.options import option
from loceval.results.document import (
    BaselineDifferenceRead,
    EstimateRead,
    ResultRead,
    read_result,
)

__all__ = [
    "FAIL_ON",
    "Gate",
    "baseline_figures",
    "check_fail_on",
    "gate_of_document",
    "gated_comparisons",
    "judge_gate",
    "parse_fail_on",
    "verdict_figures",
]

FAIL_ON: Final = tuple(str(c) for c in option("fail_on").choices)
"""The conditions ``--fail-on`` takes (``fail``, ``undecided``, ``worse``: the options table's
choices), in the order a gate reports them."""

BASELINE_WORSE: Final = "worse"
"""A baseline comparison's verdict that closes a gate with ``worse``."""


@dataclass(frozen=True, slots=True)
class Gate:
    """The gate of one evaluation.

    Attributes:
        fail_on: the conditions that close it, in :data:`FAIL_ON`'s order.
        reasons: one sentence per estimate (and condition) that closed it; empty: passed.
    """

    fail_on: tuple[str, ...]
    reasons: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        """Whether no condition of ``fail_on`` holds."""
        return not self.reasons

    def line(self) -> str:
        """Return the one line a command prints last: ``gate: ...``."""
        if self.reasons:
            return "gate: " + "; ".join(self.reasons)
        return f"gate: passed (no estimate is {_conditions(self.fail_on)})"

    def to_dict(self) -> dict[str, object]:
        """Return the JSON form: ``passed``, ``fail_on`` and ``reasons``."""
        return {"passed": self.passed, "fail_on": list(self.fail_on), "reasons": list(self.reasons)}


def _conditions(fail_on: Sequence[str]) -> str:
    words = {
        "fail": "failing the tolerance",
        "undecided": "undecided against the tolerance",
        "worse": "worse than the baseline",
    }
    said = [words[c] for c in fail_on]
    return said[0] if len(said) == 1 else ", ".join(said[:-1]) + " or " + said[-1]


def parse_fail_on(values: Iterable[str] | None) -> tuple[str, ...]:
    """Return the conditions named in ``values`` (items may hold commas), in canonical order.

    Raises:
        InputError: a name that is not a condition; the error carries ``fail_on``.
    """
    named = [v.strip().lower() for value in values or () for v in value.split(",") if v.strip()]
    unknown = [v for v in named if v not in FAIL_ON]
    if unknown:
        msg = (
            f"The gate takes the conditions {', '.join(FAIL_ON)}; {', '.join(map(repr, unknown))} "
            "is not one of them."
        )
        raise InputError(msg, option="fail_on")
    return tuple(c for c in FAIL_ON if c in named)


def check_fail_on(fail_on: Sequence[str], *, tolerance: bool, baseline: bool) -> None:
    """Refuse conditions the evaluation cannot judge (before it runs).

    Args:
        fail_on: the parsed conditions.
        tolerance: whether a tolerance is given (``fail`` and ``undecided`` judge its verdict).
        baseline: whether a baseline is given (``worse`` judges the comparison with it).

    Raises:
        InputError: a condition without what it judges; the error carries ``fail_on``.
    """
    verdicts = [c for c in fail_on if c in {"fail", "undecided"}]
    if verdicts and not tolerance:
        msg = (
            f"The gate's {' and '.join(verdicts)} judge the tolerance verdict, and no tolerance "
            "is given; give one (0.10@95: 95 % of poses within 0.10 m) or leave them out."
        )
        raise InputError(msg, option="fail_on")
    if "worse" in fail_on and not baseline:
        msg = (
            "The gate's worse judges the comparison with a baseline, and no baseline is "
            "given; name one (an earlier evaluation's result) or leave worse out."
        )
        raise InputError(msg, option="fail_on")


def verdict_figures(estimate: EstimateRead) -> str:
    """Return the figures of an estimate's verdict in brackets' words.

    ``87.2 % within 0.10 m, 95 % interval 85.0-89.1 %, needs 95 %`` (parts not written in
    the document are left out).
    """
    verdict = estimate.verdict
    if verdict is None:
        return ""
    parts = []
    if verdict.share_within is not None and verdict.tolerance_m is not None:
        parts.append(f"{verdict.share_within * 100:.1f} % within {_metres(verdict.tolerance_m)} m")
    if verdict.ci95 is not None:
        low, high = verdict.ci95
        parts.append(f"95 % interval {low * 100:.1f}–{high * 100:.1f} %")
    if verdict.required_share is not None:
        parts.append(f"needs {verdict.required_share * 100:g} %")
    return ", ".join(parts)


def _metres(value: float) -> str:
    """``0.10`` as the tolerance is usually written (centimetres); finer as it is (0.005)."""
    centimetres = value * 100
    return f"{value:.2f}" if abs(centimetres - round(centimetres)) < 1e-9 else f"{value:g}"


def _verdict_reason(estimate: EstimateRead, fail_on: Sequence[str]) -> str | None:
    verdict = estimate.verdict
    if verdict is None or verdict.outcome not in fail_on:
        return None
    figures = verdict_figures(estimate)
    bracket = f" ({figures})" if figures else ""
    if verdict.outcome == "fail":
        return f"{estimate.label} fails the tolerance{bracket}"
    return f"{estimate.label} is undecided against the tolerance{bracket}"


def baseline_figures(comparison: BaselineDifferenceRead) -> str:
    """Return a comparison with the baseline's figures in brackets' words.

    ``ATE RMSE 35.3 mm against 8.1 mm, +27.2 mm, paired 95 % interval +26.6 mm to +27.9 mm``
    (lengths in one unit for the comparison, as the report prints a group of lengths:
    :func:`loceval.core.lengths.length_unit`; parts not written in the document are left
    out).
    """
    unit = comparison.unit
    found = [
        v for v in (comparison.current, comparison.baseline, comparison.difference) if v is not None
    ]
    found += list(comparison.interval or ())
    scale = length_unit(found)

    def amount(value: float, *, sign: str = "") -> str:
        if unit == "m":
            return f"{value * scale.per_metre:{sign}.{scale.decimals}f} {scale.symbol}"
        return f"{value:{sign}.3g} {unit}".rstrip()

    parts = [BASELINE_METRICS.get(comparison.metric, comparison.metric)]
    if comparison.current is not None and comparison.baseline is not None:
        parts[0] += f" {amount(comparison.current)} against {amount(comparison.baseline)}"
    if comparison.difference is not None:
        parts.append(amount(comparison.difference, sign="+"))
    if comparison.interval is not None:
        low, high = (amount(v, sign="+") for v in comparison.interval)
        kind = "paired" if comparison.paired else "unpaired"
        parts.append(f"{kind} 95 % interval {low} to {high}")
    return ", ".join(parts)


def gated_comparisons(result: ResultRead) -> list[BaselineDifferenceRead]:
    """Return the comparisons with the baseline that are checks (the gate's ``worse``).

    A system is judged over all its trials (its ``system`` comparison); a trial's own
    comparison with the baseline's trial of the same name is shown, not judged: the runs of
    a system that is not deterministic are exchangeable, so trial 2 against the baseline's
    trial 2 says nothing a rerun would keep. An estimate that is no trial is judged itself.
    """
    if result.baseline is None:
        return []
    trials = {e.name for e in result.estimates if e.system}
    return [c for c in result.baseline.comparisons if c.level == "system" or c.name not in trials]


def _baseline_reasons(result: ResultRead) -> list[str]:
    """The comparisons with the baseline that say ``worse``, one sentence each."""
    return [
        f"{c.name}{' (over its trials)' if c.level == 'system' else ''} is worse than the "
        f"baseline ({baseline_figures(c)})"
        for c in gated_comparisons(result)
        if c.verdict == BASELINE_WORSE
    ]


def judge_gate(result: ResultRead, fail_on: Sequence[str]) -> Gate:
    """Return the gate of a result document for the conditions ``fail_on``.

    Args:
        result: the result document, read.
        fail_on: the conditions (:func:`parse_fail_on`'s).
    """
    conditions = parse_fail_on(fail_on)
    reasons = [
        reason
        for estimate in result.estimates
        if (reason := _verdict_reason(estimate, conditions)) is not None
    ]
    if "worse" in conditions:
        reasons += _baseline_reasons(result)
    return Gate(fail_on=conditions, reasons=tuple(reasons))


def gate_of_document(document: object, fail_on: Sequence[str] | None) -> dict[str, object] | None:
    """Return the gate of a stored result document as JSON (None without conditions).

    What the service shows as an evaluation's ``gate``: :func:`judge_gate` of the document
    as the command line judges its own result.

    Raises:
        InputError: the document is no result document, or a condition is unknown.
    """
    if not fail_on or document is None:
        return None
    return judge_gate(read_result(document), fail_on).to_dict()
