"""The evaluation report's view model: every number of the report computed and formatted.

:func:`build_report_view` turns an :class:`~loceval.evaluation.EvaluationResult` into a
:class:`ReportView` (statistics tables, verdicts, inputs, options, alignment, the greatest
errors, numbered figures); the templates only loop over it.
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
    describe_rpe_step,
    estimate_colour,
)
from exporters.plots.clock import plot_clock_correlation, plot_clock_drift
from exporters.plots.figure import FigureView, number_figures
from exporters.report.clocks import ClockSection, build_clock_section
from exporters.report.confidence import ConfidenceView, build_confidence_view
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
from exporters.report.verdicts import (
    BuildingView,
    VerdictView,
    building_view,
    verdict_view,
)
from loceval.core.lengths import MM_BELOW_M, LengthUnit, length_unit
from loceval.core.quantities import ARROW, ARROW_BACK
from loceval.evaluation import EvaluationResult
from loceval.metrics.pose_errors import ErrorSeries, ErrorStats
from loceval.options import option

__all__ = [
    "BEST_MARK",
    "MM_BELOW_M",
    "LengthUnit",
    "ReportView",
    "build_report_view",
    "length_unit",
]

BEST_MARK: Final = "★"
"""Marks the lowest value of a statistics row (with bold, so it survives grey print)."""

_NS_PER_S = 1_000_000_000
_STAT_ROWS: Final = (
    ("RMSE", "rmse"),
    ("MEAN", "mean"),
    ("MEDIAN", "median"),
    ("STD", "std"),
    ("MIN", "min"),
    ("MAX", "max"),
)
"""The framework paper's Tables 1-2 rows (it omits the median; the issue asks for it)."""


_TIMES_NOTE: Final = "Times in this report are seconds since the first pose of the reference."


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


def _summary(result: EvaluationResult) -> str:
    ref = result.reference
    names = [estimate_name(e, k) for k, e in enumerate(result.estimates)]
    listed = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    return (
        f"{listed} against {ref.name or 'the reference'} (ground truth): "
        f"{len(ref):,} reference poses, {ref.span_words}, {ref.length_m:.1f} m of path."
    )


def _contents(*, ranging: bool, map_section: bool, warnings: int) -> tuple[tuple[str, str], ...]:
    """Every section of the report, in order, as (anchor, title) for the contents list."""
    return tuple(
        entry
        for entry, shown in (
            (("verdict", "Verdict"), True),
            (("evaluated", "What was evaluated"), True),
            (("statistics", "Error statistics"), True),
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
    ranging = build_ranging_view(result)
    map_view = build_map_view(result)
    warnings = _warnings(result)
    shares = tuple(
        (
            f"≤ {t:g} m",
            tuple(f"{100.0 * e.within.get(t, float('nan')):.1f} %" for e in estimates),
        )
        for t in cfg.thresholds_m
    )
    return ReportView(
        title=options.title,
        evaluation_id=options.evaluation_id,
        created_at=result.created_at,
        loceval_version=result.loceval_version,
        summary=_summary(result),
        tolerance=None if cfg.tolerance is None else str(cfg.tolerance),
        verdicts=tuple(
            verdict_view(result, k, figure_of.get(f"ate_path_{k}")) for k in range(len(estimates))
        ),
        shares=shares,
        estimate_names=tuple(estimate_name(e, k) for k, e in enumerate(estimates)),
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
        confidence=build_confidence_view(
            result,
            {(t.number, "translation"): t.length.format for t in tables if t.length is not None},
        ),
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
            ranging=ranging is not None, map_section=map_view is not None, warnings=len(warnings)
        ),
        legend=scale_words(result),
        building=building_view(result),
    )
