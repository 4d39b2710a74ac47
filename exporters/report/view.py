"""The evaluation report's view model: every number of the report computed and formatted.

:func:`build_report_view` turns an :class:`~loceval.evaluation.EvaluationResult` into a
:class:`ReportView` (statistics tables, verdicts, inputs, options, alignment, the greatest
errors, numbered figures); the templates only loop over it. Its figures and words that need
no drawing (tables, verdicts, intervals, trials, baseline, warnings) come from
:func:`exporters.report.results.build_results_view`, which the CI files render too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from exporters.cad.spaces import placed_on_building
from exporters.colours import scale_words
from exporters.options import ExportOptions, FrontDoor
from exporters.plots import (
    DEFAULT_MAX_POINTS,
    REFERENCE_COLOUR,
    ImageFormat,
    Plot,
    estimate_colour,
)
from exporters.plots.clock import plot_clock_correlation, plot_clock_drift
from exporters.plots.figure import FigureView, number_figures
from exporters.report.clocks import ClockSection, build_clock_section
from exporters.report.confidence import ConfidenceView
from exporters.report.figures import ReportPlots, render_report_plots
from exporters.report.mapsection import MapView, build_map_view
from exporters.report.provenance import (
    alignment_rows,
    estimate_name,
    input_rows,
    option_rows,
    trajectory_rows,
)
from exporters.report.ranging import RangingView, build_ranging_view
from exporters.report.results import (
    ResultsView,
    StatsTable,
    build_results_view,
    unbroken_arrows,
)
from exporters.report.trials import BaselineView, TrialsView
from exporters.report.verdicts import BuildingView, VerdictView, building_view
from loceval.core.lengths import MM_BELOW_M, LengthUnit, length_unit
from loceval.evaluation import EvaluationResult
from loceval.options import option

__all__ = [
    "BEST_MARK",
    "MM_BELOW_M",
    "LengthUnit",
    "ReportView",
    "ResultsView",
    "build_report_view",
    "build_results_view",
    "length_unit",
]

BEST_MARK: Final = "★"
"""Marks the lowest value of a statistics row (with bold, so it survives grey print)."""

_NS_PER_S = 1_000_000_000
_TIMES_NOTE: Final = "Times in this report are seconds since the first pose of the reference."


@dataclass(frozen=True, slots=True)
class WorstRow:
    """One of the greatest errors."""

    rank: int
    t_s: str
    stamp_ns: int
    x: str
    y: str
    z: str
    error: str
    """The error in the table's unit (:attr:`WorstTable.error_unit`)."""


@dataclass(frozen=True, slots=True)
class WorstTable:
    """The greatest errors of one estimate."""

    name: str
    rows: tuple[WorstRow, ...]
    error_unit: str = "m"


@dataclass(frozen=True, slots=True)
class ReportView:
    """Everything the templates show, formatted (the templates compute nothing).

    Attributes:
        title: the report title.
        evaluation_id: the evaluation's id.
        created_at: when the evaluation ran (ISO 8601, UTC).
        loceval_version: the library version that computed it.
        summary: one sentence: what was evaluated against what.
        tolerance: the tolerance in words, or None.
        verdicts: one per estimate.
        shares: threshold rows of "share of poses within" (label, one value per estimate).
        estimate_names: the column heads.
        inputs: the input files (role, file, format, selector, sha256, size).
        trajectories: reference and estimates (name, role, source, poses, ...).
        options: the evaluation options as (label, value).
        alignments: the transform found: (label, one value per estimate) rows.
        tables: Tables 1 and 2.
        figures: the plots.
        worst: the greatest errors per estimate.
        warnings: (source, message) pairs.
        clocks: the "Clocks and device offset" section.
    """

    title: str
    evaluation_id: str
    created_at: str
    loceval_version: str
    summary: str
    tolerance: str | None
    verdicts: tuple[VerdictView, ...]
    shares: tuple[tuple[str, tuple[str, ...]], ...]
    estimate_names: tuple[str, ...]
    estimate_colours: tuple[str, ...]
    reference_colour: str
    inputs: tuple[Mapping[str, str], ...]
    trajectories: tuple[Mapping[str, str], ...]
    options: tuple[tuple[str, str], ...]
    alignments: tuple[tuple[str, tuple[str, ...]], ...]
    tables: tuple[StatsTable, ...]
    figures: tuple[FigureView, ...]
    worst: tuple[WorstTable, ...]
    warnings: tuple[tuple[str, str], ...]
    clocks: ClockSection
    notes: tuple[tuple[str, str], ...] = ()
    """How the inputs were read, for information (the tf chain a trajectory composes)."""
    best_mark: str = BEST_MARK
    confidence: ConfidenceView = field(default_factory=ConfidenceView)
    ranging: RangingView | None = None  # the ranging section (exporters.report.ranging)
    tolerance_example: str = ""
    """How the front door that made the report takes a tolerance (the flag, or the value)."""
    tolerance_where: str = ""
    times_note: str = _TIMES_NOTE
    """What a time in the report counts (pose numbers when the reference has no times)."""
    """Where that value goes, when the example alone does not say it (page and API)."""
    map: MapView | None = None  # the map section (exporters.report.mapsection)
    contents: tuple[tuple[str, str], ...] = ()
    """The sections in report order, as (anchor, title): the contents list of both renderings
    (the interactive view's entry is the HTML's only: the PDF keeps its figures)."""
    legend: str = ""
    """What the error colours mean: the tolerance in words (every figure and the viewer)."""
    building: BuildingView | None = None
    """The building model the paths were placed on, its spaces and warnings."""
    trials: TrialsView | None = None
    """The trials of each system (:mod:`exporters.report.trials`); None without systems."""
    baseline: BaselineView | None = None
    """Each estimate and system against the baseline; None without a baseline."""


def _worst(result: EvaluationResult) -> tuple[WorstTable, ...]:
    tables = []
    for k, e in enumerate(result.estimates):
        unit = length_unit(w.error for w in e.worst)
        rows = tuple(
            WorstRow(
                rank=r,
                t_s=f"{w.t_s:.3f}",
                stamp_ns=w.stamp_ns,
                x=f"{w.position_xyz[0]:.3f}",
                y=f"{w.position_xyz[1]:.3f}",
                z=f"{w.position_xyz[2]:.3f}",
                error=unit.format(w.error),
            )
            for r, w in enumerate(e.worst, start=1)
        )
        tables.append(WorstTable(name=estimate_name(e, k), rows=rows, error_unit=unit.symbol))
    return tuple(tables)


def _notes(result: EvaluationResult) -> tuple[tuple[str, str], ...]:
    """Information about how the inputs were read (a tf chain's links): no warnings."""
    ref_name = result.reference.name or "reference"
    out = [(f"{ref_name} (reference)", n) for n in result.reference.notes]
    for k, e in enumerate(result.estimates):
        out.extend((estimate_name(e, k), n) for n in e.estimate.notes)
    return tuple((about, unbroken_arrows(n)) for about, n in out)


def _tolerance_hint(front_door: FrontDoor) -> tuple[str, str]:
    """Return how to give a tolerance at ``front_door``: the example and what follows it.

    What follows is the example's meaning, then (page and API) where it goes: "such as
    0.10@95 (95 % of poses within 0.10 m) in the Tolerance field of the page or as
    options.tolerance in the API", one bracket (issue 44 found two in a row).
    """
    spec = option("tolerance")
    example = str(spec.example)
    metres, _, percent = example.partition("@")
    meaning = f" ({percent} % of poses within {metres} m)"
    if front_door is FrontDoor.CLI:
        return f"{spec.flag} {example}", meaning
    field_name = spec.words.removeprefix("the ").capitalize()
    return example, (
        f"{meaning} in the {field_name} field of the page or as options.{spec.key} in the API"
    )


def _contents(
    *, ranging: bool, map_section: bool, warnings: int, trials: bool = False, baseline: bool = False
) -> tuple[tuple[str, str], ...]:
    """Every section of the report, in order, as (anchor, title) for the contents list."""
    return tuple(
        entry
        for entry, shown in (
            (("verdict", "Verdict"), True),
            (("evaluated", "What was evaluated"), True),
            (("statistics", "Error statistics"), True),
            (("trials", "Trials of each system"), trials),
            (("baseline", "Against the baseline"), baseline),
            (("ranging", "Ranging"), ranging),
            (("map", "The map against the building plan"), map_section),
            (("viewer", "Interactive view"), True),
            (("plots", "Plots"), True),
            (("clocks", "Clocks and device offset"), True),
            (("worst", "Greatest errors"), True),
            (("warnings", f"Warnings ({warnings})"), True),
        )
        if shown
    )


def build_report_view(
    result: EvaluationResult,
    options: ExportOptions,
    *,
    plots: ReportPlots | Sequence[Plot] | None = None,
    image_format: ImageFormat = "svg",
    max_points: int = DEFAULT_MAX_POINTS,
) -> ReportView:
    """Compute and format everything the report shows.

    Args:
        result: the evaluation.
        options: the title and evaluation id.
        plots: already rendered plots holding ``image_format``: every figure and the clock
            section's (:func:`render_report_plots`), or the numbered figures alone (the
            clock section's is then drawn here); default: draw them all here.
        image_format: how the figures are embedded: ``svg`` for the HTML, ``png`` for the
            PDF.
        max_points: most vertices drawn per plotted line (drawing only).

    Returns:
        The view model the templates render.
    """
    result = placed_on_building(result, options)  # the stretches' rooms, the building's warnings
    if plots is None:
        plots = render_report_plots(result, options, formats=(image_format,), max_points=max_points)
    if isinstance(plots, ReportPlots):
        rendered, clock, drift = plots.figures, plots.clock, plots.clock_drift
    else:
        rendered = tuple(plots)
        clock = plot_clock_correlation(result, max_points=max_points, formats=(image_format,))
        drift = plot_clock_drift(result, formats=(image_format,))
    tolerance_example, tolerance_where = _tolerance_hint(options.front_door)
    figures = number_figures(rendered, image_format)
    figure_of = {f.key: f.number for f in figures}
    estimates = result.estimates
    maps = {
        k: figure_of[f"ate_path_{k}"] for k in range(len(estimates)) if f"ate_path_{k}" in figure_of
    }
    boxes = tuple(f.number for f in figures if f.key.startswith("trials_"))
    results = build_results_view(result, options, map_figures=maps, trial_figures=boxes)
    ranging = build_ranging_view(result)
    map_view = build_map_view(result)
    warnings = results.warnings
    tables = results.tables
    trials, baseline = results.trials, results.baseline
    return ReportView(
        title=results.title,
        evaluation_id=results.evaluation_id,
        created_at=results.created_at,
        loceval_version=result.loceval_version,
        summary=results.summary,
        tolerance=results.tolerance,
        verdicts=results.verdicts,
        shares=results.shares,
        estimate_names=results.estimate_names,
        estimate_colours=tuple(estimate_colour(k) for k in range(len(estimates))),
        reference_colour=REFERENCE_COLOUR,
        inputs=input_rows(result),
        trajectories=trajectory_rows(result),
        options=option_rows(result),
        alignments=alignment_rows(result),
        tables=tables,
        figures=figures,
        worst=_worst(result),
        warnings=warnings,
        notes=_notes(result),
        confidence=results.confidence,
        clocks=build_clock_section(
            result,
            number=len(figures) + 1,
            plot=clock,
            drift_plot=drift,
            image_format=image_format,
        ),
        ranging=ranging,
        tolerance_example=tolerance_example,
        tolerance_where=tolerance_where,
        times_note=(
            "The reference has no times (its poses are numbered, as a KITTI file without "
            "its times file): a time in this report is the pose's number, not seconds."
            if result.reference.indexed
            else _TIMES_NOTE
        ),
        map=map_view,
        contents=_contents(
            ranging=ranging is not None,
            map_section=map_view is not None,
            warnings=len(warnings),
            trials=trials is not None,
            baseline=baseline is not None,
        ),
        trials=trials,
        baseline=baseline,
        legend=scale_words(result),
        building=building_view(result),
    )
