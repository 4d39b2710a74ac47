"""The summary report of a scheduled report: many runs (recordings) of one site, one file.

Every week a site lead gets one report over the recordings a schedule selected: each run is
one evaluation (a reference and one or more estimated systems). The service builds a
:class:`SummaryInput`; this module computes everything the report shows (per-run table,
per-system statistics, the trend over time and the repeatability of the reference path)
into a view model (:class:`SummaryView`) and renders it with the evaluation report's look
(``templates/summary.html.j2``, ``templates/report.css``) as self-contained HTML (SVG
plots) and as an A4 PDF (PNG plots, WeasyPrint).

Repeatability follows the reference-robot paper's re-drive test: a path recorded once is
driven again, and the re-driven path is compared with the first in space (the paper
reports a median distance of 10.1 cm and a maximum of 24.6 cm for its robot), together
with the timing, because a system's results change with the speed it is carried at.
Comparing one system over many runs in one building is the framework paper's use (one
algorithm in different environments and runs, §2).
"""

from __future__ import annotations

import datetime as dt
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np
from matplotlib.axes import Axes
from matplotlib.dates import AutoDateLocator, ConciseDateFormatter, date2num
from numpy.typing import NDArray
from scipy.spatial import KDTree

from exporters.plots import (
    TOLERANCE_COLOUR,
    ImageFormat,
    Plot,
    _legend_above,
    _new_figure,
    _plot,
    _style,
    decimate_uniform,
    estimate_colour,
)
from exporters.report import (
    BEST_MARK,
    DEFAULT_TEMPLATES_DIR,
    check_templates,
    html_to_pdf,
    render_template,
)
from loceval import __version__

__all__ = [
    "SUMMARY_TEMPLATE_NAME",
    "PolylineIndex",
    "RepeatabilityRow",
    "SummaryFigure",
    "SummaryInput",
    "SummaryRun",
    "SummaryView",
    "SystemFigures",
    "SystemStats",
    "best_systems",
    "build_summary_view",
    "path_distances",
    "plot_paths",
    "plot_trend",
    "render_summary",
    "render_summary_html",
    "render_summary_pdf",
    "render_summary_plots",
    "render_summary_view_html",
    "repeatability",
    "system_stats",
    "tolerance_distance",
]

SUMMARY_TEMPLATE_NAME: Final = "summary.html.j2"
UTC: Final = dt.UTC
PATH_PLOT_POINTS: Final = 2000
"""Most vertices drawn per reference path in the paths-from-above figure (drawing only)."""
PATH_LEGEND_MAX: Final = 8
"""Up to this many runs are named in that figure's legend; more share one entry."""

_DASH: Final = "—"
RESAMPLE_SPACING_M: Final = 0.001
"""Spacing of the resampled baseline path: distances are within half of it (0.5 mm)."""
_MAX_SAMPLES: Final = 2_000_000
"""Most samples of the resampled baseline (its KD-tree); a path over 2 km is resampled
coarser (spacing = length / 2,000,000: still under 1 mm of error below 4 km)."""
_NEIGHBOURS: Final = 4
"""Nearest resampled vertices whose segments are measured exactly, per point."""
_CHUNK_POINTS: Final = 200_000
"""Points measured at once (bounds the memory of the exact step)."""


# --- input ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SystemFigures:
    """One estimated system's figures in one run.

    Attributes:
        ate_rmse_m: RMSE of the absolute trajectory error (translation), metres.
        rpe_rmse_m: RMSE of the relative pose error (translation), metres.
        matched: poses matched to the reference.
        verdict: ``"pass"`` or ``"fail"`` against the tolerance, None without one.
    """

    ate_rmse_m: float | None
    rpe_rmse_m: float | None
    matched: int | None
    verdict: Literal["pass", "fail"] | None


def _aware_utc(value: dt.datetime, what: str) -> dt.datetime:
    if value.tzinfo is None or value.utcoffset() is None:
        msg = f"{what} must be timezone-aware (UTC), got {value.isoformat()}."
        raise ValueError(msg)
    return value.astimezone(UTC)


def _finite(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _dig(document: Mapping[str, Any], *keys: str) -> object:
    """``document[k1][k2]...`` or None where a level is missing or not a mapping."""
    node: object = document
    for key in keys:
        if not isinstance(node, Mapping):
            return None
        node = node.get(key)
    return node


def _system_figures(estimate: Mapping[str, Any]) -> SystemFigures:
    matched = estimate.get("matched")
    verdict = estimate.get("verdict")
    passed = verdict.get("passed") if isinstance(verdict, Mapping) else None
    return SystemFigures(
        ate_rmse_m=_finite(_dig(estimate, "ate", "translation_m", "rmse")),
        rpe_rmse_m=_finite(_dig(estimate, "rpe", "translation_m", "rmse")),
        matched=matched if isinstance(matched, int) and not isinstance(matched, bool) else None,
        verdict=None if not isinstance(passed, bool) else ("pass" if passed else "fail"),
    )


@dataclass(frozen=True, slots=True)
class SummaryRun:
    """One run of the schedule: one recording's evaluation, or why it failed.

    Attributes:
        dataset: the dataset (recording) name.
        recorded_at: the run's date (the recording's upload time), aware; kept in UTC.
        status: ``"succeeded"`` or ``"failed"``.
        error: why it failed (a sentence), when it failed.
        evaluation_id: the evaluation's id, if there is one.
        systems: the figures of each estimated system, by estimate name.
        reference_xyz: (N, 3) the run's reference path, metres, for the repeatability test.
        duration_s: the reference's duration, seconds.
    """

    dataset: str
    recorded_at: dt.datetime
    status: Literal["succeeded", "failed"]
    error: str | None = None
    evaluation_id: str | None = None
    systems: Mapping[str, SystemFigures] = field(default_factory=dict)
    reference_xyz: NDArray[np.float64] | None = None
    duration_s: float | None = None

    def __post_init__(self) -> None:
        """Check the status and the path's shape; keep the date in UTC.

        Raises:
            ValueError: a naive date, an unknown status or a path that is not (N, 3).
        """
        object.__setattr__(self, "recorded_at", _aware_utc(self.recorded_at, "recorded_at"))
        if self.status not in {"succeeded", "failed"}:
            msg = f"status must be 'succeeded' or 'failed', got {self.status!r}."
            raise ValueError(msg)
        if self.reference_xyz is not None:
            xyz = np.asarray(self.reference_xyz, dtype=np.float64)
            if xyz.ndim != 2 or xyz.shape[1] != 3:
                msg = f"reference_xyz must be (N, 3), got shape {xyz.shape}."
                raise ValueError(msg)
            object.__setattr__(self, "reference_xyz", xyz)

    @classmethod
    def from_result(
        cls,
        document: Mapping[str, Any],
        *,
        dataset: str,
        recorded_at: dt.datetime,
        evaluation_id: str | None = None,
        reference_xyz: NDArray[np.float64] | None = None,
    ) -> SummaryRun:
        """Build a succeeded run from an evaluation's result document.

        The document is the CLI's ``--json`` output (``result.json``,
        :meth:`loceval.evaluation.EvaluationResult.to_dict`). Estimates without a name are
        called ``estimate 1``, ``estimate 2``, ...; a repeated name gets `` (2)``. Missing
        or non-finite figures become None (shown as a dash).

        Args:
            document: the result document.
            dataset: the dataset (recording) name.
            recorded_at: the recording's upload time, aware.
            evaluation_id: the evaluation's id.
            reference_xyz: (N, 3) the reference path, metres, for the repeatability test.

        Returns:
            The run, status ``"succeeded"``.

        Raises:
            ValueError: the document has no ``estimates`` list (it is not a result).
        """
        estimates = document.get("estimates")
        if not isinstance(estimates, Sequence) or isinstance(estimates, str | bytes):
            msg = "The result document has no 'estimates' list; is it a result.json?"
            raise ValueError(msg)  # noqa: TRY004  (a malformed document, not a type error)
        systems: dict[str, SystemFigures] = {}
        for k, estimate in enumerate(estimates):
            if not isinstance(estimate, Mapping):
                msg = f"estimates[{k}] of the result document is not an object."
                raise ValueError(msg)  # noqa: TRY004  (a malformed document, not a type error)
            raw = estimate.get("name")
            name = raw if isinstance(raw, str) and raw.strip() else f"estimate {k + 1}"
            unique, n = name, 2
            while unique in systems:
                unique, n = f"{name} ({n})", n + 1
            systems[unique] = _system_figures(estimate)
        return cls(
            dataset=dataset,
            recorded_at=recorded_at,
            status="succeeded",
            evaluation_id=evaluation_id,
            systems=systems,
            reference_xyz=reference_xyz,
            duration_s=_finite(_dig(document, "reference", "duration_s")),
        )


@dataclass(frozen=True, slots=True)
class SummaryInput:
    """What a scheduled summary report covers.

    Attributes:
        title: the report title (``"Weekly site report: Level 2"``).
        generated_at: when the report was made, aware; kept in UTC.
        selection: which recordings were selected, in words (``"recordings tagged level-2
            uploaded in the 7 days before 2026-11-23 07:00 UTC"``).
        runs: the runs, in any order (the report sorts them by ``recorded_at``).
        tolerance: the tolerance in words (``"0.10 m for 95 % of poses"``), or None.
        notes: sentences for the reader (``"The service was down at 07:00; ..."``).
        schedule_id: the schedule's id.
        run_id: this run of the schedule.
    """

    title: str
    generated_at: dt.datetime
    selection: str
    runs: Sequence[SummaryRun]
    tolerance: str | None = None
    notes: Sequence[str] = ()
    schedule_id: str | None = None
    run_id: str | None = None

    def __post_init__(self) -> None:
        """Keep the generation time in UTC.

        Raises:
            ValueError: ``generated_at`` is naive.
        """
        object.__setattr__(self, "generated_at", _aware_utc(self.generated_at, "generated_at"))


def _sorted_runs(runs: Sequence[SummaryRun]) -> list[SummaryRun]:
    """Runs by ``recorded_at``; runs at the same time keep their given order."""
    return sorted(runs, key=lambda r: r.recorded_at)


# --- statistics -------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SystemStats:
    """One system over all succeeded runs that evaluated it.

    Attributes:
        name: the system (estimate name).
        runs: succeeded runs that evaluated it.
        ate_rmse_m: its ATE RMSE per run (runs without one left out), metres.
        rpe_rmse_m: its RPE RMSE per run (runs without one left out), metres.
        passed: runs whose verdict is pass.
        judged: runs with a verdict.
    """

    name: str
    runs: int
    ate_rmse_m: tuple[float, ...]
    rpe_rmse_m: tuple[float, ...]
    passed: int
    judged: int

    @property
    def ate_mean(self) -> float | None:
        """Mean ATE RMSE over the runs, or None without values."""
        return float(np.mean(self.ate_rmse_m)) if self.ate_rmse_m else None

    @property
    def ate_std(self) -> float | None:
        """Standard deviation (population, ``ddof=0``) of the ATE RMSE over the runs."""
        return float(np.std(self.ate_rmse_m)) if self.ate_rmse_m else None

    @property
    def rpe_mean(self) -> float | None:
        """Mean RPE RMSE over the runs, or None without values."""
        return float(np.mean(self.rpe_rmse_m)) if self.rpe_rmse_m else None

    @property
    def rpe_std(self) -> float | None:
        """Standard deviation (population, ``ddof=0``) of the RPE RMSE over the runs."""
        return float(np.std(self.rpe_rmse_m)) if self.rpe_rmse_m else None

    @property
    def pass_rate(self) -> float | None:
        """Share of the judged runs that passed, or None when no run had a verdict."""
        return self.passed / self.judged if self.judged else None


def _system_names(runs: Sequence[SummaryRun]) -> list[str]:
    """Every system name, in order of first appearance in the runs sorted by date."""
    names: dict[str, None] = {}
    for run in _sorted_runs(runs):
        if run.status == "succeeded":
            names.update(dict.fromkeys(run.systems))
    return list(names)


def system_stats(runs: Sequence[SummaryRun]) -> list[SystemStats]:
    """Each system's figures over all succeeded runs, in order of first appearance.

    Args:
        runs: the runs (failed ones are left out).

    Returns:
        One entry per system.
    """
    ordered = [r for r in _sorted_runs(runs) if r.status == "succeeded"]
    out = []
    for name in _system_names(ordered):
        figures = [r.systems[name] for r in ordered if name in r.systems]
        out.append(
            SystemStats(
                name=name,
                runs=len(figures),
                ate_rmse_m=tuple(f.ate_rmse_m for f in figures if f.ate_rmse_m is not None),
                rpe_rmse_m=tuple(f.rpe_rmse_m for f in figures if f.rpe_rmse_m is not None),
                passed=sum(f.verdict == "pass" for f in figures),
                judged=sum(f.verdict is not None for f in figures),
            )
        )
    return out


def best_systems(stats: Sequence[SystemStats]) -> list[str]:
    """The system(s) with the lowest mean ATE RMSE, as printed (3 decimals); ties share it."""
    printed = {s.name: round(s.ate_mean, 3) for s in stats if s.ate_mean is not None}
    if not printed:
        return []
    lowest = min(printed.values())
    return [name for name, value in printed.items() if value == lowest]


# --- repeatability ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RepeatabilityRow:
    """One run's reference path against the first run's (the baseline), in space.

    Attributes:
        dataset: the run's dataset.
        recorded_at: the run's date.
        evaluation_id: the run's evaluation.
        points: reference positions compared.
        baseline: whether this is the first run (the one the others are compared with).
        median_m: median distance from this run's positions to the baseline's path, metres
            (None for the baseline).
        max_m: largest such distance, metres (None for the baseline).
        duration_s: this run's reference duration, seconds.
        duration_diff_s: this run's duration minus the baseline's, seconds (None for the
            baseline or when a duration is unknown).
    """

    dataset: str
    recorded_at: dt.datetime
    evaluation_id: str | None
    points: int
    baseline: bool
    median_m: float | None
    max_m: float | None
    duration_s: float | None
    duration_diff_s: float | None


def _finite_rows(xyz: NDArray[np.float64]) -> NDArray[np.float64]:
    out: NDArray[np.float64] = xyz[np.isfinite(xyz).all(axis=1)]
    return out


@dataclass(frozen=True, slots=True)
class PolylineIndex:
    """A polyline resampled densely into a KD-tree, to measure many points against it.

    Samples are placed every ``spacing`` metres along the path (and at its end), each
    tagged with the segment it lies on. Any point of the polyline then lies within
    ``spacing / 2`` of a sample, so the nearest sample to a query point is at most
    ``spacing / 2`` farther than the polyline itself. The exact point-to-segment distance to
    the segments of the few nearest samples is therefore never below the true distance and
    at most ``spacing / 2`` above it.

    Attributes:
        vertices: (M, 3) the polyline (a single vertex is doubled into one segment).
        samples: (S, 3) the resampled points.
        segment: (S,) the segment each sample lies on.
        spacing: the spacing along the path, metres (the error bound is half of it).
        tree: the KD-tree over ``samples``.
    """

    vertices: NDArray[np.float64]
    samples: NDArray[np.float64]
    segment: NDArray[np.intp]
    spacing: float
    tree: KDTree

    @classmethod
    def build(
        cls, vertices_xyz: NDArray[np.float64], *, spacing: float = RESAMPLE_SPACING_M
    ) -> PolylineIndex:
        """Resample a polyline at ``spacing`` (coarser past 2,000,000 samples) and index it.

        Raises:
            ValueError: the polyline has no vertex.
        """
        vertices = np.asarray(vertices_xyz, dtype=np.float64).reshape(-1, 3)
        if len(vertices) == 0:
            msg = "The polyline has no vertex."
            raise ValueError(msg)
        if len(vertices) == 1:
            vertices = np.vstack([vertices, vertices])  # one zero-length segment
        ab = np.diff(vertices, axis=0)
        length = np.linalg.norm(ab, axis=1)
        along = np.concatenate([[0.0], np.cumsum(length)])
        total = float(along[-1])
        spacing = max(spacing, total / _MAX_SAMPLES, 1e-9)
        # Uniform in arc length (across vertices), so a densely recorded path is not
        # sampled more finely than needed; the last vertex closes it.
        at = np.append(np.arange(0.0, total, spacing), total)
        segment = np.clip(np.searchsorted(along, at, side="right") - 1, 0, len(ab) - 1)
        fraction = np.divide(
            at - along[segment],
            length[segment],
            out=np.zeros_like(at),
            where=length[segment] > 0.0,
        )
        samples = vertices[segment] + np.clip(fraction, 0.0, 1.0)[:, None] * ab[segment]
        segment = segment.astype(np.intp)
        tree = KDTree(samples, compact_nodes=False)  # faster queries far from the path
        return cls(vertices, samples, segment, spacing, tree)

    def distances(self, points_xyz: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance from each point to the polyline, metres.

        Never below the exact distance and at most ``spacing / 2`` above it (0.5 mm at
        the default spacing). Vectorised: the points are handled in chunks, not one by one.

        Args:
            points_xyz: (N, 3) points.

        Returns:
            (N,) distances.
        """
        points = np.asarray(points_xyz, dtype=np.float64).reshape(-1, 3)
        a, ab = self.vertices[:-1], np.diff(self.vertices, axis=0)
        length2 = np.einsum("ij,ij->i", ab, ab)
        k = min(_NEIGHBOURS, len(self.samples))
        out = np.empty(len(points))
        for start in range(0, len(points), _CHUNK_POINTS):  # chunks of points, not each point
            p = points[start : start + _CHUNK_POINTS]
            _, idx = self.tree.query(p, k=k)
            seg = self.segment[np.asarray(idx, dtype=np.intp).reshape(len(p), k)]
            sa, sab, sl2 = a[seg], ab[seg], length2[seg]
            along = np.einsum("pkj,pkj->pk", p[:, None, :] - sa, sab)
            t = np.divide(along, sl2, out=np.zeros_like(along), where=sl2 > 0.0)
            diff = p[:, None, :] - sa - np.clip(t, 0.0, 1.0)[..., None] * sab
            out[start : start + len(p)] = np.sqrt(np.einsum("pkj,pkj->pk", diff, diff)).min(1)
        return out


def path_distances(
    points_xyz: NDArray[np.float64], vertices_xyz: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance from each point to a polyline (point-to-segment), fast for long paths.

    See :class:`PolylineIndex`: at most 0.5 mm above the exact distance for paths up to
    2 km, never below it.

    Args:
        points_xyz: (N, 3) points, metres.
        vertices_xyz: (M, 3) polyline vertices, M >= 1.

    Returns:
        (N,) distances, metres.

    Raises:
        ValueError: the polyline has no vertex.
    """
    return PolylineIndex.build(vertices_xyz).distances(points_xyz)


def _runs_with_path(runs: Sequence[SummaryRun]) -> list[tuple[SummaryRun, NDArray[np.float64]]]:
    """The runs with a reference path (its finite positions), by ``recorded_at``."""
    out = []
    for run in _sorted_runs(runs):
        if run.reference_xyz is not None:
            xyz = _finite_rows(run.reference_xyz)
            if len(xyz):
                out.append((run, xyz))
    return out


def repeatability(runs: Sequence[SummaryRun]) -> list[RepeatabilityRow]:
    """Compare every run's reference path with the first run's, in space (not by time).

    The runs with a reference path are taken by ``recorded_at``; the first is the
    baseline. For each later run, every reference position's distance to the baseline's
    path (a polyline through its positions, point-to-segment) is measured; the median and
    the largest summarise how closely the path was re-driven. The duration difference
    tells whether it was driven at the same pace.

    Args:
        runs: the runs, in any order; those without ``reference_xyz`` (or with no finite
            position) are left out.

    Returns:
        The baseline's row first, then one row per later run with a path.
    """
    with_path = _runs_with_path(runs)
    if not with_path:
        return []
    (first, first_xyz), later = with_path[0], with_path[1:]

    rows = [
        RepeatabilityRow(
            dataset=first.dataset,
            recorded_at=first.recorded_at,
            evaluation_id=first.evaluation_id,
            points=len(first_xyz),
            baseline=True,
            median_m=None,
            max_m=None,
            duration_s=first.duration_s,
            duration_diff_s=None,
        )
    ]
    if not later:
        return rows
    index = PolylineIndex.build(first_xyz)  # once for every later run
    for run, xyz in later:
        distances = index.distances(xyz)
        diff = (
            None
            if run.duration_s is None or first.duration_s is None
            else run.duration_s - first.duration_s
        )
        rows.append(
            RepeatabilityRow(
                dataset=run.dataset,
                recorded_at=run.recorded_at,
                evaluation_id=run.evaluation_id,
                points=len(xyz),
                baseline=False,
                median_m=float(np.median(distances)),
                max_m=float(distances.max()),
                duration_s=run.duration_s,
                duration_diff_s=diff,
            )
        )
    return rows


# --- view model -------------------------------------------------------------------------


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
    dataset: str
    evaluation_id: str
    failed: bool
    error: str
    cells: tuple[SystemCell, ...]


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


@dataclass(frozen=True, slots=True)
class SummaryFigure:
    """A numbered figure of the summary."""

    number: int
    key: str
    title: str
    caption: str
    src: str


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


def _m(value: float | None) -> str:
    return _DASH if value is None else f"{value:.3f}"


def _date(value: dt.datetime) -> str:
    return value.astimezone(UTC).strftime("%Y-%m-%d %H:%M")


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
            date=_date(run.recorded_at),
            date_iso=run.recorded_at.isoformat(timespec="seconds"),
            dataset=run.dataset,
            evaluation_id=run.evaluation_id or "",
            failed=run.status == "failed",
            error=(run.error or "The run failed; no reason was recorded.")
            if run.status == "failed"
            else "",
            cells=tuple(_cell(run.systems.get(name)) for name in names),
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
    return tuple(notes)


def _repeatability_view(rows: Sequence[RepeatabilityRow]) -> tuple[RepeatabilityView, ...]:
    return tuple(
        RepeatabilityView(
            date=_date(r.recorded_at),
            dataset=r.dataset,
            points=f"{r.points:,}",
            baseline=r.baseline,
            median_m="baseline" if r.baseline else _m(r.median_m),
            max_m="" if r.baseline else _m(r.max_m),
            duration_s=_DASH if r.duration_s is None else f"{r.duration_s:.1f}",
            duration_diff_s=""
            if r.baseline
            else (_DASH if r.duration_diff_s is None else f"{r.duration_diff_s:+.1f}"),
        )
        for r in rows
    )


def _repeatability_lead(rows: Sequence[RepeatabilityRow], runs: int) -> str:
    if not rows:
        return "No run carries its reference path, so the re-driven paths cannot be compared."
    base = rows[0]
    if len(rows) == 1:
        return (
            f"Only one run ({base.dataset}, {_date(base.recorded_at)}) carries its reference "
            "path, so there is no re-drive to compare with it yet."
        )
    later = [r for r in rows[1:] if r.median_m is not None]
    worst = max(later, key=lambda r: r.median_m or 0.0)
    skipped = runs - len(rows)
    text = (
        f"{_plural(len(later), 'run')} compared with the first, {base.dataset} "
        f"({_date(base.recorded_at)}). The largest median distance is "
        f"{_m(worst.median_m)} m ({worst.dataset}, {_date(worst.recorded_at)})."
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
    runs = _sorted_runs(summary.runs)
    failed = sum(r.status == "failed" for r in runs)
    succeeded = len(runs) - failed
    names = _system_names(runs)
    stats = system_stats(runs)
    best = best_systems(stats)
    rep_rows = repeatability(runs) if repeatability_rows is None else repeatability_rows
    rendered = (
        tuple(plots)
        if plots is not None
        else render_summary_plots(summary, formats=(image_format,))
    )
    figures = tuple(
        SummaryFigure(
            number=n,
            key=p.key,
            title=p.title,
            caption=p.caption,
            src=p.data_uri(image_format),
        )
        for n, p in enumerate(rendered, start=1)
    )
    figure_of = {f.key: f.number for f in figures}
    empty = not runs
    return SummaryView(
        title=summary.title,
        generated_at=_date(summary.generated_at) + " UTC",
        generated_at_iso=summary.generated_at.isoformat(timespec="seconds"),
        selection=summary.selection,
        tolerance=summary.tolerance,
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
                _date(r.recorded_at),
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
        stats_notes=_stats_notes(stats, succeeded) if stats else (),
        figures=figures,
        trend_figure=figure_of.get("trend"),
        paths_figure=figure_of.get("paths_xy"),
        repeatability=_repeatability_view(rep_rows),
        repeatability_lead=_repeatability_lead(rep_rows, len(runs)),
    )


# --- plots ------------------------------------------------------------------------------


def _date_axis(ax: Axes, times: Sequence[dt.datetime]) -> None:
    """Dates along x (UTC), padded so one run or runs at one time still get an axis."""
    lo, hi = min(times), max(times)
    pad = max((hi - lo) * 0.04, dt.timedelta(hours=12))
    left, right = date2num([lo - pad, hi + pad])  # type: ignore[no-untyped-call]
    ax.set_xlim(float(left), float(right))
    locator = AutoDateLocator(tz=UTC, minticks=3, maxticks=8)  # type: ignore[no-untyped-call]
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(ConciseDateFormatter(locator, tz=UTC))  # type: ignore[no-untyped-call]


def plot_trend(
    summary: SummaryInput,
    *,
    formats: Sequence[ImageFormat] = ("svg",),
    tolerance_m: float | None = None,
) -> Plot | None:
    """ATE RMSE and RPE RMSE of each system against the run date; None without figures.

    Args:
        summary: the runs.
        formats: the encodings to produce.
        tolerance_m: the tolerance distance drawn dashed on the ATE row, if any.

    Returns:
        The figure, or None when no succeeded run has a figure to draw.
    """
    runs = _sorted_runs(summary.runs)
    names = _system_names(runs)
    done = [r for r in runs if r.status == "succeeded"]
    rows = (("ATE RMSE [m]", "ate_rmse_m"), ("RPE RMSE [m]", "rpe_rmse_m"))
    if not any(
        getattr(r.systems[name], attr) is not None
        for r in done
        for name in names
        if name in r.systems
        for _, attr in rows
    ):
        return None
    many = len(runs) > 20
    fig = _new_figure(1.3 + 1.75 * len(rows))
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    failed_at = [r.recorded_at for r in runs if r.status == "failed"]
    tops = dict.fromkeys((attr for _, attr in rows), 0.0)
    for ax, (label, attr) in zip(axes, rows, strict=True):
        for k, name in enumerate(names):
            points = [
                (r.recorded_at, value)
                for r in done
                if name in r.systems and (value := getattr(r.systems[name], attr)) is not None
            ]
            if not points:
                continue
            tops[attr] = max(tops[attr], *(v for _, v in points))
            ax.plot(
                [t for t, _ in points],
                [v for _, v in points],
                color=estimate_colour(k),
                linewidth=1.0 if many else 1.3,
                marker="o",
                markersize=3.0 if many else 5.0,
                label=name,
            )
        if attr == "ate_rmse_m" and tolerance_m is not None:
            ax.axhline(
                tolerance_m,
                color=TOLERANCE_COLOUR,
                linestyle="--",
                linewidth=1.0,
                label=f"tolerance {tolerance_m:g} m",
            )
        if failed_at:
            ax.plot(
                failed_at,
                [0.0] * len(failed_at),
                linestyle="none",
                marker="x",
                markersize=6,
                color="#616161",
                clip_on=False,
                zorder=5,
                label="failed run",
            )
        ax.set_ylabel(label)
        # Head room over the highest point and the tolerance line, so neither sits on the edge.
        top = max(tops[attr], tolerance_m or 0.0 if attr == "ate_rmse_m" else 0.0, 0.01 / 1.15)
        ax.set_ylim(0.0, 1.15 * top)
        _style(ax)
    _date_axis(axes[-1], [r.recorded_at for r in runs])
    axes[-1].set_xlabel("recorded (UTC)")
    _legend_above(fig, axes[0])
    caption = (
        "Each system's RMSE per run against the run's recording date: the absolute error "
        "after alignment (top) and the error of the motion per step (bottom)."
    )
    if tolerance_m is not None:
        caption += (
            f" The dashed line is the tolerance distance ({tolerance_m:g} m); the verdict "
            "asks a share of poses within it, so an RMSE below the line is not by itself "
            "a pass."
        )
    if failed_at:
        caption += " Grey crosses on the time axis are runs that failed."
    if len(runs) == 1:
        caption += " With one run each system is a single point."
    return _plot(fig, formats, key="trend", title="Errors over the runs", caption=caption)


def plot_paths(
    runs: Sequence[SummaryRun], *, formats: Sequence[ImageFormat] = ("svg",)
) -> Plot | None:
    """The reference paths from above (x-y): the baseline in black, later runs over it.

    Args:
        runs: the runs; those with ``reference_xyz`` are drawn.
        formats: the encodings to produce.

    Returns:
        The figure, or None with fewer than two paths.
    """
    with_path = _runs_with_path(runs)
    if len(with_path) < 2:
        return None
    paths = [(run, xyz[decimate_uniform(len(xyz), PATH_PLOT_POINTS)]) for run, xyz in with_path]
    every = np.concatenate([xy[:, :2] for _, xy in paths])
    span = np.ptp(every, axis=0)
    ratio = 1.0 if span[0] <= 0 else float(span[1] / span[0])
    fig = _new_figure(float(np.clip(6.2 * ratio, 2.6, 7.0)) + 1.2)
    ax = fig.add_subplot()
    named = len(paths) <= PATH_LEGEND_MAX
    later_colour = "#3b4cc0"
    for k, (row, xyz) in enumerate(paths[1:], start=1):
        label = (
            f"{_date(row.recorded_at)} {row.dataset}"
            if named
            else (f"later runs ({len(paths) - 1})" if k == 1 else None)
        )
        ax.plot(
            xyz[:, 0],
            xyz[:, 1],
            color=estimate_colour(k + 2) if named else later_colour,
            linewidth=0.9,
            alpha=0.8 if named else 0.35,
            label=label,
        )
    base_row, base = paths[0]
    ax.plot(
        base[:, 0],
        base[:, 1],
        color="black",
        linewidth=1.8,
        zorder=4,
        label=f"baseline: {_date(base_row.recorded_at)} {base_row.dataset}",
    )
    ax.plot(
        [base[0, 0]],
        [base[0, 1]],
        marker="o",
        markersize=7,
        markerfacecolor="white",
        markeredgecolor="black",
        linestyle="none",
        zorder=5,
        label="start of the baseline",
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    _style(ax)
    _legend_above(fig, ax)
    return _plot(
        fig,
        formats,
        key="paths_xy",
        title="Reference paths from above (x-y)",
        caption=(
            "The reference (ground-truth) path of every run with one, in the reference "
            "system's frame: the first run (the baseline) in black, the later runs over it."
        ),
    )


_DISTANCE_WORDS: Final = re.compile(r"(\d+(?:\.\d*)?|\.\d+)\s*(mm|cm|m)\b", re.IGNORECASE)
_DISTANCE_AT: Final = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*@")
_UNIT_M: Final = {"mm": 0.001, "cm": 0.01, "m": 1.0}


def tolerance_distance(tolerance: str | None) -> float | None:
    """The tolerance distance in metres, read from its words.

    The first number with a length unit counts: ``"0.10 m for 95 % of poses"`` and
    ``"95 % of poses within 0.1 m"`` (how :class:`loceval.evaluation.Tolerance` prints)
    give 0.1, ``"10 cm ..."`` 0.1; the CLI's ``"0.10@95"`` gives 0.1. Anything else gives
    None (no tolerance line is drawn).
    """
    if tolerance is None:
        return None
    found = _DISTANCE_WORDS.search(tolerance)
    if found is not None:
        value = float(found.group(1)) * _UNIT_M[found.group(2).lower()]
    elif (at := _DISTANCE_AT.match(tolerance)) is not None:
        value = float(at.group(1))
    else:
        return None
    return value if math.isfinite(value) and value > 0 else None


def render_summary_plots(
    summary: SummaryInput, *, formats: Sequence[ImageFormat] = ("svg",)
) -> tuple[Plot, ...]:
    """Render the summary's figures: the trend and, with two paths or more, the paths.

    Args:
        summary: the runs.
        formats: the encodings to produce from each figure.

    Returns:
        The figures in report order (none for an empty selection).
    """
    plots = [
        plot_trend(summary, formats=formats, tolerance_m=tolerance_distance(summary.tolerance)),
        plot_paths(summary.runs, formats=formats),
    ]
    return tuple(p for p in plots if p is not None)


# --- rendering --------------------------------------------------------------------------


def _templates(templates_dir: Path | None) -> Path:
    return check_templates(
        templates_dir or DEFAULT_TEMPLATES_DIR, SUMMARY_TEMPLATE_NAME, label="summary"
    )


def render_summary_view_html(view: SummaryView, *, templates_dir: Path) -> bytes:
    """Render a summary view model to HTML (UTF-8).

    Raises:
        ExportUnavailableError: Jinja2 is not installed.
        ExportError: the templates are missing or broken.
    """
    return render_template(
        _templates(templates_dir),
        SUMMARY_TEMPLATE_NAME,
        label="summary",
        requirement="The summary report",
        summary=view,
    )


def render_summary_html(summary: SummaryInput, *, templates_dir: Path) -> bytes:
    """Render the summary as one self-contained HTML file (SVG plots).

    Raises:
        ExportUnavailableError: Jinja2 or matplotlib is missing.
        ExportError: the templates are missing or broken.
    """
    folder = _templates(templates_dir)
    return render_summary_view_html(build_summary_view(summary), templates_dir=folder)


def render_summary_pdf(summary: SummaryInput, *, templates_dir: Path) -> bytes:
    """Render the summary as an A4 PDF (PNG plots, WeasyPrint).

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or WeasyPrint is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates(templates_dir)
    view = build_summary_view(summary, image_format="png")
    return html_to_pdf(render_summary_view_html(view, templates_dir=folder))


def render_summary(summary: SummaryInput, *, templates_dir: Path) -> tuple[bytes, bytes]:
    """Render the summary as HTML and PDF, drawing each plot once for both formats.

    Args:
        summary: the runs and what they are.
        templates_dir: the template folder (the repository's ``templates/``).

    Returns:
        ``(html, pdf)`` as bytes.

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or WeasyPrint is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = _templates(templates_dir)
    plots = render_summary_plots(summary, formats=("svg", "png"))
    rows = repeatability(summary.runs)
    html = render_summary_view_html(
        build_summary_view(summary, image_format="svg", plots=plots, repeatability_rows=rows),
        templates_dir=folder,
    )
    printable = render_summary_view_html(
        build_summary_view(summary, image_format="png", plots=plots, repeatability_rows=rows),
        templates_dir=folder,
    )
    return html, html_to_pdf(printable)
