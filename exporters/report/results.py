"""The report's figures and words without its plots: what the CI files show too.

:func:`build_results_view` computes and formats, from an evaluation, everything of the
report that is no drawing: Tables 1-2 with their intervals, the verdicts, the shares within
the thresholds, the trials of each system, the comparisons with the baseline, the warnings
and the gate. :func:`exporters.report.view.build_report_view` takes these from here (adding
the figures, inputs and sections that need drawing), and ``junit.xml`` and ``summary.md``
(:mod:`exporters.ci`) render the same :class:`ResultsView`: a figure is computed and
formatted once for all of them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from exporters.options import ExportOptions
from exporters.plots import describe_rpe_step
from exporters.report.confidence import ConfidenceView, build_confidence_view
from exporters.report.provenance import estimate_name
from exporters.report.trials import (
    BaselineView,
    TrialsView,
    build_baseline_view,
    build_trials_view,
)
from exporters.report.verdicts import VerdictView, verdict_view
from loceval.assessment.baseline import BASELINE_METRICS
from loceval.core.lengths import MM_BELOW_M, LengthUnit, length_unit
from loceval.core.quantities import ARROW, ARROW_BACK
from loceval.evaluation import EvaluationResult
from loceval.metrics.pose_errors import ErrorSeries, ErrorStats
from loceval.results.document import ResultRead, read_result
from loceval.results.gate import Gate, gated_comparisons, judge_gate

__all__ = [
    "Cell",
    "ResultsView",
    "StatsRow",
    "StatsTable",
    "build_results_view",
    "unbroken_arrows",
]

_STAT_ROWS: Final = (
    ("RMSE", "rmse"),
    ("MEAN", "mean"),
    ("MEDIAN", "median"),
    ("STD", "std"),
    ("MIN", "min"),
    ("MAX", "max"),
)
"""The framework paper's Tables 1-2 rows (it omits the median; the issue asks for it)."""


@dataclass(frozen=True, slots=True)
class Cell:
    """One value of a statistics table, formatted with its unit, and whether it is best."""

    text: str
    best: bool = False


@dataclass(frozen=True, slots=True)
class StatsRow:
    """A row of a statistics table: ``RMSE``, ``MEAN``, ... with one cell per estimate."""

    label: str
    cells: tuple[Cell, ...]


@dataclass(frozen=True, slots=True)
class StatsTable:
    """The framework paper's table layout: metrics down, estimates across."""

    number: int
    title: str
    note: str
    columns: tuple[str, ...]
    groups: tuple[tuple[str, tuple[StatsRow, ...]], ...]
    marks_best: bool
    length: LengthUnit | None = None
    """The unit of the translation rows (their intervals are printed in it too)."""


def _fmt(value: float, decimals: int = 3) -> str:
    return f"{value:.{decimals}f}"


def _stats_rows(
    series: Sequence[ErrorSeries | None], unit: str, *, mark: bool, scale: LengthUnit | None = None
) -> tuple[StatsRow, ...]:
    stats: list[ErrorStats | None] = [None if s is None else s.stats for s in series]
    rows = []
    for label, attr in _STAT_ROWS:
        printed = [
            None
            if st is None
            else (_fmt if scale is None else scale.format)(float(getattr(st, attr)))
            for st in stats
        ]
        # Best is decided on the printed values, so equal-looking numbers are marked alike.
        numbers = [float(t) for t in printed if t is not None]
        best = min(numbers) if numbers else None
        cells = tuple(
            Cell("—") if text is None else Cell(f"{text}{unit}", best=mark and float(text) == best)
            for text in printed
        )
        rows.append(StatsRow(label=label, cells=cells))
    return tuple(rows)


def _stats_table(
    result: EvaluationResult,
    *,
    number: int,
    title: str,
    note: str,
    translation: Sequence[ErrorSeries],
    rotation: Sequence[ErrorSeries | None],
) -> StatsTable:
    mark = len(result.estimates) > 1
    columns = tuple(
        f"{estimate_name(e, k)} (n = {len(t):,})"
        for k, (e, t) in enumerate(zip(result.estimates, translation, strict=True))
    )
    unit = length_unit(float(getattr(t.stats, attr)) for t in translation for _, attr in _STAT_ROWS)
    groups: list[tuple[str, tuple[StatsRow, ...]]] = [
        ("translation", _stats_rows(translation, f" {unit.symbol}", mark=mark, scale=unit))
    ]
    if any(r is not None for r in rotation):
        groups.append(("rotation", _stats_rows(rotation, "°", mark=mark)))
    in_unit = (
        f" Translation in millimetres: every value of this table is below {MM_BELOW_M:g} m."
        if unit.symbol == "mm"
        else ""
    )
    return StatsTable(
        number=number,
        title=title,
        note=note + in_unit,
        columns=columns,
        groups=tuple(groups),
        marks_best=mark,
        length=unit,
    )


def unbroken_arrows(text: str) -> str:
    """Return ``text`` with each arrow of a tf chain bound to its frames (no line splits)."""
    return text.replace(f" {ARROW} ", f"\u00a0{ARROW}\u00a0").replace(
        f" {ARROW_BACK} ", f"\u00a0{ARROW_BACK}\u00a0"
    )


def _warnings(result: EvaluationResult) -> tuple[tuple[str, str], ...]:
    ref_name = result.reference.name or "reference"
    out = [(f"{ref_name} (reference)", w) for w in result.reference_warnings]
    for k, e in enumerate(result.estimates):
        out.extend((estimate_name(e, k), w) for w in e.warnings)
    # Why two estimates were not compared is about the pair, not about the reference.
    out.extend(("comparison of estimates", w) for w in result.comparison_notes)
    if result.building is not None:  # how the model is placed: an up axis, the site
        out.extend(("building model", w) for w in result.building.warnings)
    return tuple((about, unbroken_arrows(w)) for about, w in out)


def _summary(result: EvaluationResult) -> str:
    ref = result.reference
    names = [estimate_name(e, k) for k, e in enumerate(result.estimates)]
    listed = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    return (
        f"{listed} against {ref.name or 'the reference'} (ground truth): "
        f"{len(ref):,} reference poses, {ref.span_words}, {ref.length_m:.1f} m of path."
    )


def _judged(document: ResultRead) -> frozenset[tuple[str, str]]:
    """The baseline rows that are checks, as (row name, metric in words)."""
    return frozenset(
        (c.name + (" (system)" if c.level == "system" else ""), BASELINE_METRICS[c.metric])
        for c in gated_comparisons(document)
        if c.metric in BASELINE_METRICS
    )


@dataclass(frozen=True, slots=True)
class ResultsView:
    """The report's figures and words without its plots: what CI files show too.

    :func:`build_report_view` takes its verdicts, tables, intervals, shares, trials and
    baseline sections from here, and
    ``junit.xml`` and ``summary.md`` (:mod:`exporters.ci`) render the same object, so a
    figure is computed and formatted once for all three.

    Attributes:
        title: the report title.
        evaluation_id: the evaluation's id.
        created_at: when the evaluation ran (ISO 8601, UTC).
        summary: one sentence: what was evaluated against what.
        tolerance: the tolerance in words, or None.
        estimate_names: one per estimate, in order.
        verdicts: one per estimate.
        shares: threshold rows of "share of poses within" (label, one value per estimate).
        tables: Tables 1 (ATE) and 2 (RPE).
        confidence: the intervals of the tables, the comparisons of estimates, NEES.
        warnings: (source, message) pairs.
        gate: the gate of the options' ``fail_on`` (None without conditions).
        trials: the trials of each system (None without systems).
        baseline: each estimate and system against the baseline (None without one).
        judged: the baseline rows that are checks, as (row name, metric): the gate's
            ``worse`` judges them (:func:`loceval.results.gate.gated_comparisons`); a
            trial's own comparison is shown, not judged.
        estimate_systems: each estimate's system ("" when it is no trial).
    """

    title: str
    evaluation_id: str
    created_at: str
    summary: str
    tolerance: str | None
    estimate_names: tuple[str, ...]
    verdicts: tuple[VerdictView, ...]
    shares: tuple[tuple[str, tuple[str, ...]], ...]
    tables: tuple[StatsTable, ...]
    confidence: ConfidenceView
    warnings: tuple[tuple[str, str], ...]
    gate: Gate | None = None
    trials: TrialsView | None = None
    baseline: BaselineView | None = None
    judged: frozenset[tuple[str, str]] = frozenset()
    estimate_systems: tuple[str, ...] = ()

    def figure(self, table: int, label: str, column: int, group: str = "translation") -> str:
        """Return a Table 1-2 value with its unit and interval (``0.194 m (0.180–0.210)``).

        Args:
            table: 1 (ATE) or 2 (RPE).
            label: the row (``RMSE``, ``MEAN``, ...).
            column: the estimate's index.
            group: ``translation`` or ``rotation``.

        Returns:
            The text, or ``—`` when the table has no such value.
        """
        found = next(t for t in self.tables if t.number == table)
        rows = dict(found.groups).get(group, ())
        row = next((r for r in rows if r.label == label), None)
        if row is None or column >= len(row.cells) or row.cells[column].text == "—":
            return "—"
        return row.cells[column].text + self.confidence.suffix(table, group, label, column)


def build_results_view(
    result: EvaluationResult,
    options: ExportOptions,
    *,
    map_figures: Mapping[int, int] | None = None,
    trial_figures: tuple[int, ...] = (),
) -> ResultsView:
    """Compute and format the report's figures and words, without drawing anything.

    Args:
        result: the evaluation (placed on its building, when it has one).
        options: the title, the evaluation id and the gate's conditions.
        map_figures: per estimate the number of its error map in the report, where its
            verdict's stretches are numbered (none outside the report).
        trial_figures: the numbers of the trials' box plots in the report (none outside).
    """
    estimates = result.estimates
    cfg = result.config
    tables = (
        _stats_table(
            result,
            number=1,
            title="Absolute Trajectory Error (ATE)",
            note="Distance between each aligned estimate pose and the ground truth at the same "
            "time.",
            translation=[e.ate_translation for e in estimates],
            rotation=[e.ate_rotation for e in estimates],
        ),
        _stats_table(
            result,
            number=2,
            title="Relative Pose Error (RPE)",
            note=f"Error of the motion over each step of {describe_rpe_step(cfg)} "
            "(drift per step).",
            translation=[e.rpe_translation for e in estimates],
            rotation=[e.rpe_rotation for e in estimates],
        ),
    )
    shares = tuple(
        (
            f"≤ {t:g} m",
            tuple(f"{100.0 * e.within.get(t, float('nan')):.1f} %" for e in estimates),
        )
        for t in cfg.thresholds_m
    )
    figure_of = map_figures or {}
    document = read_result(result.to_dict())  # the systems and the baseline, read as written
    gate = judge_gate(document, options.fail_on) if options.fail_on else None
    return ResultsView(
        title=options.title,
        evaluation_id=options.evaluation_id,
        created_at=result.created_at,
        summary=_summary(result),
        tolerance=None if cfg.tolerance is None else str(cfg.tolerance),
        estimate_names=tuple(estimate_name(e, k) for k, e in enumerate(estimates)),
        verdicts=tuple(verdict_view(result, k, figure_of.get(k)) for k in range(len(estimates))),
        shares=shares,
        tables=tables,
        confidence=build_confidence_view(
            result,
            {(t.number, "translation"): t.length.format for t in tables if t.length is not None},
        ),
        warnings=_warnings(result),
        gate=gate,
        trials=build_trials_view(result, trial_figures),
        baseline=build_baseline_view(result),
        judged=_judged(document),
        estimate_systems=tuple(e.system or "" for e in estimates),
    )
