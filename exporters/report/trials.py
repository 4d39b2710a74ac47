"""The report's trials and baseline sections: their view models, every figure formatted.

"Trials of each system" shows, per system and metric, the figures over its trials
(:mod:`loceval.assessment.trials`): median, mean, spread and the 95 % interval over trials,
the failed trials with why, and the systems compared over all their trials; the box plots
are numbered figures of the Plots section. "Against the baseline" shows each estimate's and
system's difference from the baseline (:mod:`loceval.assessment.baseline`) with its interval
and verdict. Both renderings (HTML, Typst) loop over these.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Final

from loceval.assessment.baseline import BASELINE_METRICS
from loceval.assessment.trials import MIN_TRIALS_FOR_INTERVAL, TRIAL_METRICS
from loceval.core.lengths import length_unit
from loceval.evaluation import EvaluationResult

__all__ = ["BaselineView", "TrialsView", "build_baseline_view", "build_trials_view"]

VERDICT_WORDS: Final[Mapping[str, str]] = {
    "better": "better",
    "worse": "worse",
    "within_noise": "within noise",
    "undetermined": "undetermined",
}
"""A baseline verdict in the report's words."""

TRIALS_NOTE: Final = (
    "Each trial is one run of the system on this reference. Spread: the sample standard "
    "deviation, the range (min to max) and the interquartile range. The 95 % interval is the "
    "Student-t interval of the mean over trials, given from "
    f"{MIN_TRIALS_FOR_INTERVAL} trials on; with fewer there are too few trials for one. A "
    "failed trial (its evaluation failed, or it tracked less of the run than the least "
    "coverage) is listed, not averaged."
)
COMPARISONS_NOTE: Final = (
    "Systems compared over all their trials: the shift is the Hodges-Lehmann median of the "
    "differences of per-trial values, its interval the distribution-free Moses interval, and "
    "p the two-sided Mann-Whitney rank-sum test."
)
BASELINE_NOTE: Final = (
    "Difference = now minus baseline (negative: better now). Paired where both keep per-pose "
    "errors at shared stamps (a paired block bootstrap); otherwise unpaired (the MOVER "
    "combination of the two 95 % intervals); a system over all its trials. Better or worse: "
    "the whole 95 % interval is below or above 0; within noise: it holds 0."
)


@dataclass(frozen=True, slots=True)
class TrialRow:
    """One metric of one system over its trials, formatted."""

    system: str
    metric: str
    trials: str
    median: str
    mean: str
    std: str
    range: str
    iqr: str
    interval: str


@dataclass(frozen=True, slots=True)
class FailedRow:
    """A failed trial: its system, name and why."""

    system: str
    name: str
    reason: str


@dataclass(frozen=True, slots=True)
class TrialsView:
    """The "Trials of each system" section.

    Attributes:
        rows: one per system and metric.
        failed: every failed trial.
        comparisons: one sentence per two systems and metric.
        figures: the box plots' figure numbers, as "Figures 6 to 9" (empty without).
        note: how the figures over trials are made.
        comparisons_note: how systems are compared.
    """

    rows: tuple[TrialRow, ...]
    failed: tuple[FailedRow, ...]
    comparisons: tuple[str, ...]
    figures: str
    note: str = TRIALS_NOTE
    comparisons_note: str = COMPARISONS_NOTE


@dataclass(frozen=True, slots=True)
class BaselineRow:
    """One figure now against the baseline's, formatted."""

    name: str
    metric: str
    now: str
    baseline: str
    difference: str
    interval: str
    how: str
    verdict: str
    status: str
    """``better``, ``worse``, ``within_noise`` or ``undetermined`` (the row's colour)."""


@dataclass(frozen=True, slots=True)
class BaselineView:
    """The "Against the baseline" section.

    Attributes:
        label: the baseline's name.
        source: where it came from, in words.
        rows: one per estimate or system and metric.
        notes: names without a counterpart, and what reading the baseline found.
        note: how the differences are made and judged.
    """

    label: str
    source: str
    rows: tuple[BaselineRow, ...]
    notes: tuple[str, ...]
    note: str = BASELINE_NOTE


Format = Callable[[float], str]


def _formatter(unit: str, values: Iterable[float]) -> tuple[str, Format]:
    """The symbol and the number format of a unit (metres: one length unit for all values)."""
    if unit == "m":
        scale = length_unit(abs(v) for v in values)
        return scale.symbol, scale.format
    return ("°" if unit == "deg" else unit), (lambda v: f"{v:.3f}")


def _text(value: float, unit: str, fmt: Format) -> str:
    return f"{fmt(value)}{unit}" if unit in {"°", "%"} else f"{fmt(value)} {unit}"


def _span(low: float, high: float, unit: str, fmt: Format) -> str:
    """``low to high unit``, the unit once."""
    return f"{fmt(low)} to {_text(high, unit, fmt)}"


def build_trials_view(
    result: EvaluationResult, figure_numbers: tuple[int, ...]
) -> TrialsView | None:
    """Return the trials section, or None when no estimate names a system.

    Args:
        result: the evaluation.
        figure_numbers: the numbers of the box-plot figures, in order.
    """
    if not result.systems:
        return None
    rows = []
    every = [m for s in result.systems for m in s.metrics.values()]
    formats = {
        unit: _formatter(unit, [v for m in every if m.unit == unit for v in (m.min, m.max)])
        for unit in {m.unit for m in every}
    }
    for system in result.systems:
        trials = f"{len(system.trials)}" + (
            f" ({len(system.failed)} failed)" if system.failed else ""
        )
        for key, m in system.metrics.items():
            unit, fmt = formats[m.unit]
            interval = (
                _span(m.interval.low, m.interval.high, unit, fmt)
                if m.interval is not None
                else "too few trials"
            )
            rows.append(
                TrialRow(
                    system=system.name,
                    metric=TRIAL_METRICS[key],
                    trials=trials,
                    median=_text(m.median, unit, fmt),
                    mean=_text(m.mean, unit, fmt),
                    std=_text(m.std, unit, fmt),
                    range=_span(m.min, m.max, unit, fmt),
                    iqr=_text(m.iqr, unit, fmt),
                    interval=interval,
                )
            )
        if not system.metrics:
            rows.append(
                TrialRow(system.name, "—", trials, "—", "—", "—", "—", "—", "no trial succeeded")
            )
    if not figure_numbers:
        figures = ""
    elif len(figure_numbers) == 1:
        figures = f"Figure {figure_numbers[0]}"
    else:
        figures = f"Figures {figure_numbers[0]} to {figure_numbers[-1]}"
    return TrialsView(
        rows=tuple(rows),
        failed=tuple(FailedRow(f.system, f.name, f.reason) for f in result.failed_trials),
        comparisons=tuple(c.summary for c in result.system_comparisons),
        figures=figures,
    )


def build_baseline_view(result: EvaluationResult) -> BaselineView | None:
    """Return the baseline section, or None without a baseline."""
    found = result.baseline
    if found is None:
        return None
    rows = []
    formats = {
        unit: _formatter(
            unit, [v for d in found.differences if d.unit == unit for v in (d.current, d.baseline)]
        )
        for unit in {d.unit for d in found.differences}
    }
    for d in found.differences:
        unit, fmt = formats[d.unit]
        sign = "+" if d.difference > 0 else ""
        interval = "—" if d.interval is None else _span(*d.interval, unit, fmt)
        rows.append(
            BaselineRow(
                name=d.name + (" (system)" if d.level == "system" else ""),
                metric=BASELINE_METRICS[d.metric],
                now=_text(d.current, unit, fmt),
                baseline=_text(d.baseline, unit, fmt),
                difference=sign + _text(d.difference, unit, fmt),
                interval=interval,
                how="paired" if d.paired else "over trials" if d.level == "system" else "unpaired",
                verdict=VERDICT_WORDS[d.verdict],
                status=d.verdict,
            )
        )
    source = f"{found.label} ({'an evo result' if found.kind == 'evo' else 'a loceval result'})"
    return BaselineView(label=found.label, source=source, rows=tuple(rows), notes=found.notes)
