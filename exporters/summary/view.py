"""The summary report's view model: every figure and sentence formatted for the templates.

:func:`build_summary_view` computes the runs table, the side-by-side statistics, the
repeatability table and the lead sentences from a :class:`SummaryInput` and formats them
into a :class:`SummaryView`; the templates only loop over it.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, Literal

from exporters.plots import ImageFormat, Plot, estimate_colour
from exporters.plots.figure import FigureView, number_figures
from exporters.report import BEST_MARK
from exporters.summary.comparisons import across_runs
from exporters.summary.model import (
    UTC,
    RepeatabilityRow,
    SummaryInput,
    SummaryRun,
    SystemFigures,
    SystemStats,
    best_systems,
    date_text,
    repeatability,
    sorted_runs,
    system_names,
    system_stats,
)
from exporters.summary.plots import render_summary_plots
from loceval import __version__

__all__ = [
    "RepeatabilityView",
    "RunRowView",
    "SummaryFigure",
    "SummaryView",
    "SystemCell",
    "SystemStatsView",
    "build_summary_view",
]

_DASH: Final = "—"


@dataclass(frozen=True, slots=True)
class SystemCell:
    """One system's cells in a run's row."""

    ate: str
    rpe: str
    status: str  # "pass", "fail", "none" (no verdict) or "missing" (not evaluated)
    badge: str


@dataclass(frozen=True, slots=True)
class RunRowView:
    """One run of the runs table."""

    number: int
    date: str
    date_iso: str
    uploaded: bool
    dataset: str
    evaluation_id: str
    failed: bool
    error: str
    cells: tuple[SystemCell, ...]
    source: str = "loceval"
    source_note: str = ""


@dataclass(frozen=True, slots=True)
class SystemStatsView:
    """One system's row of the side-by-side table."""

    name: str
    colour: str
    runs: str
    ate_mean: str
    ate_std: str
    ate_min: str
    ate_max: str
    rpe_mean: str
    rpe_std: str
    rpe_min: str
    rpe_max: str
    pass_rate: str
    best: bool


@dataclass(frozen=True, slots=True)
class RepeatabilityView:
    """One row of the repeatability table."""

    date: str
    dataset: str
    points: str
    baseline: bool
    median_m: str
    max_m: str
    duration_s: str
    duration_diff_s: str
    timing_median_s: str = ""
    timing_max_s: str = ""
    timing_stretches: str = ""


SummaryFigure = FigureView
"""A numbered figure of the summary (the same view as the evaluation report's figures)."""


@dataclass(frozen=True, slots=True)
class SummaryView:
    """Everything the summary templates show, formatted (the templates compute nothing).

    Attributes:
        title: the report title.
        generated_at: when it was made, ``YYYY-MM-DD HH:MM UTC``.
        generated_at_iso: the same in ISO 8601.
        selection: the selection in words.
        tolerance: the tolerance in words, or None.
        notes: sentences for the reader.
        schedule_id: the schedule's id, or "".
        run_id: this run of the schedule, or "".
        loceval_version: the library version that made the report.
        empty: whether no recording matched the selection.
        empty_statement: the sentence saying so ("" otherwise).
        lead: sentences summing the report up.
        runs_count: ``"12 (11 evaluated, 1 failed)"``.
        failed_runs: ``(date, dataset, reason)`` of each failed run.
        any_succeeded: whether any run has figures.
        system_names: the system columns.
        system_colours: their colours (as in the plots).
        system_columns: the table columns the systems take (at least 1).
        runs: the runs table.
        stats: the side-by-side table.
        best_sentence: which system had the lowest mean ATE RMSE, in one sentence.
        stats_notes: remarks under the side-by-side table.
        figures: the plots.
        trend_figure: the number of the trend figure, or None.
        paths_figure: the number of the paths-from-above figure, or None.
        repeatability: the repeatability table (baseline first).
        repeatability_lead: a sentence on the repeatability (or why there is none).
        best_mark: the mark of the best mean ATE RMSE.
    """

    title: str
    generated_at: str
    generated_at_iso: str
    selection: str
    tolerance: str | None
    notes: tuple[str, ...]
    schedule_id: str
    run_id: str
    loceval_version: str
    empty: bool
    empty_statement: str
    lead: tuple[str, ...]
    runs_count: str
    failed_runs: tuple[tuple[str, str, str], ...]
    any_succeeded: bool
    system_names: tuple[str, ...]
    system_colours: tuple[str, ...]
    system_columns: int
    runs: tuple[RunRowView, ...]
    stats: tuple[SystemStatsView, ...]
    best_sentence: str
    stats_notes: tuple[str, ...]
    figures: tuple[SummaryFigure, ...]
    trend_figure: int | None
    paths_figure: int | None
    repeatability: tuple[RepeatabilityView, ...]
    repeatability_lead: str
    best_mark: str = BEST_MARK
    baseline: BaselineSection | None = None
    """Each run against the schedule's pinned baseline; None when no run has one."""


@dataclass(frozen=True, slots=True)
class BaselineRowView:
    """One run's estimate or system against the baseline, formatted."""

    date: str
    dataset: str
    name: str
    metric: str
    difference: str
    interval: str
    verdict: str
    status: str


@dataclass(frozen=True, slots=True)
class BaselineSection:
    """The summary's "Against the baseline" section: each run's figures against it."""

    label: str
    rows: tuple[BaselineRowView, ...]
    note: str = (
        "Difference = the run minus the baseline, metres (negative: better now), with its 95 % "
        "interval (paired on shared stamps, otherwise the two intervals combined); better or "
        "worse: the whole interval is below or above 0; within noise: it holds 0."
    )


_BASELINE_WORDS: Final = {
    "better": "better",
    "worse": "worse",
    "within_noise": "within noise",
    "undetermined": "undetermined",
}


def _signed(value: float | None) -> str:
    return _DASH if value is None else f"{value:+.3f}"


def _baseline_section(runs: Sequence[SummaryRun]) -> BaselineSection | None:
    with_baseline = [r for r in runs if r.baseline]
    if not with_baseline:
        return None
    labels = sorted({r.baseline_label for r in with_baseline if r.baseline_label})
    rows = tuple(
        BaselineRowView(
            date=date_text(r.recorded_at),
            dataset=r.dataset,
            name=line.name,
            metric=line.metric,
            difference=_signed(line.difference_m),
            interval=_DASH
            if line.interval_m is None
            else f"{_signed(line.interval_m[0])} to {_signed(line.interval_m[1])}",
            verdict=_BASELINE_WORDS.get(line.verdict, line.verdict),
            status=line.verdict,
        )
        for r in with_baseline
        for line in r.baseline
    )
    return BaselineSection(label=", ".join(labels), rows=rows)


def _m(value: float | None) -> str:
    return _DASH if value is None else f"{value:.3f}"


def _day(value: dt.datetime) -> str:
    return value.astimezone(UTC).strftime("%Y-%m-%d")


def _plural(n: int, word: str, plural: str | None = None) -> str:
    return f"{n:,} {word if n == 1 else (plural or word + 's')}"


def _cell(figures: SystemFigures | None) -> SystemCell:
    if figures is None:
        return SystemCell(ate=_DASH, rpe=_DASH, status="missing", badge="not evaluated")
    status = figures.verdict or "none"
    return SystemCell(
        ate=_m(figures.ate_rmse_m),
        rpe=_m(figures.rpe_rmse_m),
        status=status,
        badge={"pass": "PASS", "fail": "FAIL"}.get(status, _DASH),
    )


def _run_rows(runs: Sequence[SummaryRun], names: Sequence[str]) -> tuple[RunRowView, ...]:
    return tuple(
        RunRowView(
            number=n,
            date=date_text(run.recorded_at),
            date_iso=run.recorded_at.isoformat(timespec="seconds"),
            uploaded=run.recorded_at_is_upload,
            dataset=run.dataset,
            evaluation_id=run.evaluation_id or "",
            failed=run.status == "failed",
            error=(run.error or "The run failed; no reason was recorded.")
            if run.status == "failed"
            else "",
            cells=tuple(_cell(run.systems.get(name)) for name in names),
            source=run.source,
            source_note=run.source_note or "",
        )
        for n, run in enumerate(runs, start=1)
    )


def _range(values: Sequence[float], pick: Literal["min", "max"]) -> str:
    if not values:
        return _DASH
    return _m(min(values) if pick == "min" else max(values))


def _stats_view(stats: Sequence[SystemStats], best: Sequence[str]) -> tuple[SystemStatsView, ...]:
    mark = len(stats) > 1
    rows = []
    for k, s in enumerate(stats):
        rate = s.pass_rate
        rows.append(
            SystemStatsView(
                name=s.name,
                colour=estimate_colour(k),
                runs=f"{s.runs:,}",
                ate_mean=_m(s.ate_mean),
                ate_std=_m(s.ate_std),
                ate_min=_range(s.ate_rmse_m, "min"),
                ate_max=_range(s.ate_rmse_m, "max"),
                rpe_mean=_m(s.rpe_mean),
                rpe_std=_m(s.rpe_std),
                rpe_min=_range(s.rpe_rmse_m, "min"),
                rpe_max=_range(s.rpe_rmse_m, "max"),
                pass_rate=_DASH
                if rate is None
                else f"{rate * 100:.0f} % ({s.passed:,} of {s.judged:,})",
                best=mark and s.name in best,
            )
        )
    return tuple(rows)


def _best_sentence(stats: Sequence[SystemStats], best: Sequence[str]) -> str:
    by_name = {s.name: s for s in stats}
    winners = [by_name[name] for name in best]
    if not winners:
        return ""
    w = winners[0]
    figures = (
        f"{_m(w.ate_mean)} m (std {_m(w.ate_std)} m)"
        if len(winners) == 1
        else f"{_m(w.ate_mean)} m"
    )
    if len(stats) == 1:
        return (
            f"{w.name} had a mean ATE RMSE of {_m(w.ate_mean)} m (std {_m(w.ate_std)} m) "
            f"over {_plural(len(w.ate_rmse_m), 'run')}."
        )
    if len(winners) == 1:
        return (
            f"{w.name} had the lowest mean ATE RMSE over {_plural(len(w.ate_rmse_m), 'run')}: "
            f"{figures}."
        )
    names = ", ".join(x.name for x in winners[:-1]) + " and " + winners[-1].name
    return f"{names} share the lowest mean ATE RMSE: {figures}."


def _evo_note(runs: Sequence[SummaryRun]) -> tuple[str, ...]:
    """Say which rows are evo's figures, and what they lack, when any is."""
    evo = sum(r.source == "evo" and r.status == "succeeded" for r in runs)
    if not evo:
        return ()
    note = (
        f"{_plural(evo, 'row')} marked evo {'is' if evo == 1 else 'are'} an uploaded result "
        "zip of evo_ape or evo_rpe: evo's RMSE as evo computed it (its association and "
        "alignment, named in the row), counted with the others in the statistics. evo gives "
        "no confidence interval and judges no tolerance, so these rows have no verdict (—)."
    )
    return (note,)


def _stats_notes(stats: Sequence[SystemStats], succeeded: int) -> tuple[str, ...]:
    notes = [
        (
            "Mean, std (standard deviation, population), min and max are taken over the "
            "per-run RMSE of each system, one value per succeeded run that evaluated it."
        )
    ]
    if len(stats) > 1:
        notes.append(f"{BEST_MARK} marks the lowest mean ATE RMSE (the most accurate system here).")
    if len({s.runs for s in stats}) > 1:
        notes.append(
            "The systems were not evaluated on the same runs: compare their figures with care."
        )
    if 0 < succeeded < 3:
        notes.append(f"Only {_plural(succeeded, 'run')} evaluated: too few to judge the spread.")
    notes.extend(across_runs(stats))
    return tuple(notes)


def _repeatability_view(rows: Sequence[RepeatabilityRow]) -> tuple[RepeatabilityView, ...]:
    return tuple(
        RepeatabilityView(
            date=date_text(r.recorded_at),
            dataset=r.dataset,
            points=f"{r.points:,}",
            baseline=r.baseline,
            median_m="baseline" if r.baseline else _m(r.median_m),
            max_m="" if r.baseline else _m(r.max_m),
            duration_s=_DASH if r.duration_s is None else f"{r.duration_s:.1f}",
            duration_diff_s=""
            if r.baseline
            else (_DASH if r.duration_diff_s is None else f"{r.duration_diff_s:+.1f}"),
            **_timing_cells(r),
        )
        for r in rows
    )


def _timing_cells(row: RepeatabilityRow) -> dict[str, str]:
    """The timing columns: median and largest |difference|, stretches over the tolerance."""
    if row.baseline:
        return {}
    timing = row.timing
    if timing is None:
        return {"timing_median_s": _DASH, "timing_max_s": _DASH, "timing_stretches": _DASH}
    stretches = ", ".join(
        f"{s.start_s:.0f} s +{s.duration_s:.0f} s ({s.max_abs_s:+.1f} s)"
        for s in timing.stretches[:3]
    )
    more = len(timing.stretches) - 3
    return {
        "timing_median_s": f"{timing.median_abs_s:.2f}",
        "timing_max_s": f"{timing.max_abs_s:.2f}",
        "timing_stretches": (stretches + (f" and {more} more" if more > 0 else "")) or "none",
    }


def _repeatability_lead(rows: Sequence[RepeatabilityRow], runs: int) -> str:
    if not rows:
        return "No run carries its reference path, so the re-driven paths cannot be compared."
    base = rows[0]
    if len(rows) == 1:
        return (
            f"Only one run ({base.dataset}, {date_text(base.recorded_at)}) carries its reference "
            "path, so there is no re-drive to compare with it yet."
        )
    later = [r for r in rows[1:] if r.median_m is not None]
    worst = max(later, key=lambda r: r.median_m or 0.0)
    skipped = runs - len(rows)
    text = (
        f"{_plural(len(later), 'run')} compared with the first, {base.dataset} "
        f"({date_text(base.recorded_at)}). The largest median distance is "
        f"{_m(worst.median_m)} m ({worst.dataset}, {date_text(worst.recorded_at)})."
    )
    if skipped:
        verb = "is" if skipped == 1 else "are"
        text += f" {_plural(skipped, 'run')} without a reference path {verb} left out."
    return text


def _lead(runs: Sequence[SummaryRun], failed: int) -> tuple[str, ...]:
    n = len(runs)
    first, last = _day(runs[0].recorded_at), _day(runs[-1].recorded_at)
    when = f"on {first}" if first == last else f"from {first} to {last}"
    evaluated = n - failed
    text = f"{_plural(n, 'recording')} {when}: {evaluated:,} evaluated"
    text += f", {failed:,} failed." if failed else "."
    return (text,)


def build_summary_view(
    summary: SummaryInput,
    *,
    image_format: ImageFormat = "svg",
    plots: Sequence[Plot] | None = None,
    repeatability_rows: Sequence[RepeatabilityRow] | None = None,
) -> SummaryView:
    """Compute and format everything the summary report shows.

    Args:
        summary: the runs and what they are.
        image_format: how the figures are embedded: ``svg`` for the HTML, ``png`` for the
            PDF.
        plots: already rendered plots holding ``image_format`` (default: render them here).
        repeatability_rows: :func:`repeatability` of the runs, when already computed.

    Returns:
        The view model the templates render.
    """
    runs = sorted_runs(summary.runs)
    failed = sum(r.status == "failed" for r in runs)
    succeeded = len(runs) - failed
    names = system_names(runs)
    stats = system_stats(runs)
    best = best_systems(stats)
    rep_rows = repeatability(runs) if repeatability_rows is None else repeatability_rows
    rendered = (
        tuple(plots)
        if plots is not None
        else render_summary_plots(summary, formats=(image_format,))
    )
    figures = number_figures(rendered, image_format)
    figure_of = {f.key: f.number for f in figures}
    empty = not runs
    return SummaryView(
        title=summary.title,
        generated_at=date_text(summary.generated_at) + " UTC",
        generated_at_iso=summary.generated_at.isoformat(timespec="seconds"),
        selection=summary.selection,
        tolerance=None if summary.tolerance is None else str(summary.tolerance),
        notes=tuple(summary.notes),
        schedule_id=summary.schedule_id or "",
        run_id=summary.run_id or "",
        loceval_version=__version__,
        empty=empty,
        empty_statement=f"No recordings matched the selection ({summary.selection})."
        if empty
        else "",
        lead=() if empty else _lead(runs, failed),
        runs_count=f"{len(runs):,}"
        + (f" ({succeeded:,} evaluated, {failed:,} failed)" if failed else ""),
        failed_runs=tuple(
            (
                date_text(r.recorded_at),
                r.dataset,
                r.error or "The run failed; no reason was recorded.",
            )
            for r in runs
            if r.status == "failed"
        ),
        any_succeeded=succeeded > 0,
        system_names=tuple(names),
        system_colours=tuple(estimate_colour(k) for k in range(len(names))),
        system_columns=max(3 * len(names), 1),
        runs=_run_rows(runs, names),
        stats=_stats_view(stats, best),
        best_sentence=_best_sentence(stats, best),
        stats_notes=(_stats_notes(stats, succeeded) if stats else ()) + _evo_note(runs),
        figures=figures,
        trend_figure=figure_of.get("trend"),
        paths_figure=figure_of.get("paths_xy"),
        repeatability=_repeatability_view(rep_rows),
        repeatability_lead=_repeatability_lead(rep_rows, len(runs)),
        baseline=_baseline_section(runs),
    )
