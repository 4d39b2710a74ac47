"""The summary report's input and what it computes from it: runs, statistics, repeatability.

A schedule's service builds a :class:`SummaryInput` (one :class:`SummaryRun` per selected
recording); :func:`system_stats` sums each system up over the runs and :func:`repeatability`
compares every run's reference path with the first run's, in space, through the core's
:func:`loceval.metrics.repeatability.path_deviations`.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Literal

import numpy as np
from numpy.typing import NDArray

from loceval.errors import InputError
from loceval.evaluation import Tolerance
from loceval.metrics.redrive import RedriveTiming, redrive_timing
from loceval.metrics.repeatability import finite_positions, path_deviations
from loceval.results.document import EstimateRead, read_result

__all__ = [
    "BaselineLine",
    "RepeatabilityRow",
    "SummaryInput",
    "SummaryRun",
    "SystemFigures",
    "SystemStats",
    "best_systems",
    "date_text",
    "repeatability",
    "runs_with_path",
    "sorted_runs",
    "system_names",
    "system_stats",
]

UTC: Final = dt.UTC


def date_text(value: dt.datetime) -> str:
    """A date as the report prints it: ``YYYY-MM-DD HH:MM`` in UTC."""
    return value.astimezone(UTC).strftime("%Y-%m-%d %H:%M")


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


@dataclass(frozen=True, slots=True)
class BaselineLine:
    """One estimate's or system's figure in one run against the schedule's pinned baseline.

    Attributes:
        name: the estimate or system (``orb (system)``).
        metric: ``ATE RMSE`` or ``RPE RMSE``.
        difference_m: now minus baseline, metres (negative: better now).
        interval_m: its 95 % interval, or None.
        verdict: ``better``, ``worse``, ``within_noise`` or ``undetermined``.
    """

    name: str
    metric: str
    difference_m: float | None
    interval_m: tuple[float, float] | None
    verdict: str


def _aware_utc(value: dt.datetime, what: str) -> dt.datetime:
    if value.tzinfo is None or value.utcoffset() is None:
        msg = f"{what} must be timezone-aware (UTC), got {value.isoformat()}."
        raise ValueError(msg)
    return value.astimezone(UTC)


def _system_figures(estimate: EstimateRead) -> SystemFigures:
    verdict = estimate.verdict
    return SystemFigures(
        ate_rmse_m=estimate.rmse_m("ate"),
        rpe_rmse_m=estimate.rmse_m("rpe"),
        matched=estimate.matched,
        verdict=None if verdict is None else ("pass" if verdict.passed else "fail"),
    )


@dataclass(frozen=True, slots=True)
class SummaryRun:
    """One run of the schedule: one recording's evaluation, or why it failed.

    Attributes:
        dataset: the dataset (recording) name.
        recorded_at: the run's date: when the recording started (from its stamps), or its
            upload time when its stamps are not dates; aware; kept in UTC.
        status: ``"succeeded"`` or ``"failed"``.
        error: why it failed (a sentence), when it failed.
        evaluation_id: the evaluation's id, if there is one.
        systems: the figures of each estimated system, by estimate name.
        reference_xyz: (N, 3) the run's reference path, metres, for the repeatability test.
        duration_s: the reference's duration, seconds.
        recorded_at_is_upload: ``recorded_at`` is the upload time (the table marks it).
        reference_t_s: (N,) the reference's times (seconds), one per ``reference_xyz`` row,
            for the re-drive timing (:mod:`loceval.metrics.redrive`); None leaves timing out.
        source: who computed the figures: ``"loceval"`` (an evaluation of this run) or
            ``"evo"`` (an uploaded result zip of evo_ape/evo_rpe, taken as evo wrote it).
        source_note: what the figures are when they are not loceval's own (the zip's
            metric, pose relation and alignment, and what it lacks), one sentence.
        baseline: the run's figures against its evaluation's baseline (a schedule's pinned
            evaluation), in metres; empty without a baseline.
        baseline_label: the baseline's name ("" without one).
    """

    dataset: str
    recorded_at: dt.datetime
    status: Literal["succeeded", "failed"]
    error: str | None = None
    evaluation_id: str | None = None
    systems: Mapping[str, SystemFigures] = field(default_factory=dict)
    reference_xyz: NDArray[np.float64] | None = None
    duration_s: float | None = None
    recorded_at_is_upload: bool = False
    reference_t_s: NDArray[np.float64] | None = None
    source: Literal["loceval", "evo"] = "loceval"
    source_note: str | None = None
    baseline: tuple[BaselineLine, ...] = ()
    baseline_label: str = ""

    def __post_init__(self) -> None:
        """Check the status and the path's shape; keep the date in UTC.

        Raises:
            ValueError: a naive date, an unknown status or a path that is not (N, 3).
        """
        object.__setattr__(self, "recorded_at", _aware_utc(self.recorded_at, "recorded_at"))
        if self.status not in {"succeeded", "failed"}:
            msg = f"status must be 'succeeded' or 'failed', got {self.status!r}."
            raise ValueError(msg)
        if self.source not in {"loceval", "evo"}:
            msg = f"source must be 'loceval' or 'evo', got {self.source!r}."
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
        recorded_at_is_upload: bool = False,
        reference_t_s: NDArray[np.float64] | None = None,
    ) -> SummaryRun:
        """Build a succeeded run from an evaluation's result document.

        The document is the CLI's ``--json`` output (``result.json``,
        :meth:`loceval.evaluation.EvaluationResult.to_dict`), read through
        :func:`loceval.results.document.read_result`. Estimates without a name are
        called ``estimate 1``, ``estimate 2``, ...; a repeated name gets `` (2)``. Missing
        or non-finite figures become None (shown as a dash).

        Args:
            document: the result document.
            dataset: the dataset (recording) name.
            recorded_at: when the recording started (or its upload time), aware.
            evaluation_id: the evaluation's id.
            reference_xyz: (N, 3) the reference path, metres, for the repeatability test.
            recorded_at_is_upload: ``recorded_at`` is the upload time.
            reference_t_s: (N,) the reference's times, seconds, for the re-drive timing.

        Returns:
            The run, status ``"succeeded"``.

        Raises:
            ValueError: the document has no ``estimates`` list (it is not a result), or one
                is not an object.
        """
        try:
            read = read_result(document)
        except InputError as err:
            raise ValueError(str(err)) from None
        systems: dict[str, SystemFigures] = {}
        for estimate in read.estimates:
            unique, n = estimate.label, 2
            while unique in systems:
                unique, n = f"{estimate.label} ({n})", n + 1
            systems[unique] = _system_figures(estimate)
        return cls(
            dataset=dataset,
            recorded_at=recorded_at,
            status="succeeded",
            evaluation_id=evaluation_id,
            systems=systems,
            reference_xyz=reference_xyz,
            reference_t_s=reference_t_s,
            duration_s=read.reference_duration_s,
            recorded_at_is_upload=recorded_at_is_upload,
            baseline=()
            if read.baseline is None
            else tuple(
                BaselineLine(
                    name=c.name + (" (system)" if c.level == "system" else ""),
                    metric="ATE RMSE" if c.metric == "ate_rmse" else "RPE RMSE",
                    difference_m=c.difference,
                    interval_m=c.interval,
                    verdict=c.verdict,
                )
                for c in read.baseline.comparisons
                if c.unit == "m"
            ),
            baseline_label="" if read.baseline is None else read.baseline.label,
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
        tolerance: the application tolerance the verdicts were judged against, or None.
        notes: sentences for the reader (``"The service was down at 07:00; ..."``).
        schedule_id: the schedule's id.
        run_id: this run of the schedule.
    """

    title: str
    generated_at: dt.datetime
    selection: str
    runs: Sequence[SummaryRun]
    tolerance: Tolerance | None = None
    notes: Sequence[str] = ()
    schedule_id: str | None = None
    run_id: str | None = None

    def __post_init__(self) -> None:
        """Keep the generation time in UTC.

        Raises:
            ValueError: ``generated_at`` is naive.
        """
        object.__setattr__(self, "generated_at", _aware_utc(self.generated_at, "generated_at"))


def sorted_runs(runs: Sequence[SummaryRun]) -> list[SummaryRun]:
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


def system_names(runs: Sequence[SummaryRun]) -> list[str]:
    """Every system name, in order of first appearance in the runs sorted by date."""
    names: dict[str, None] = {}
    for run in sorted_runs(runs):
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
    ordered = [r for r in sorted_runs(runs) if r.status == "succeeded"]
    out = []
    for name in system_names(ordered):
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
        timing: when this run passed the baseline's points against when the baseline did
            (:func:`loceval.metrics.redrive.redrive_timing`); None for the baseline or
            without times.
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
    timing: RedriveTiming | None = None


def runs_with_path(runs: Sequence[SummaryRun]) -> list[tuple[SummaryRun, NDArray[np.float64]]]:
    """The runs with a reference path (its finite positions), by ``recorded_at``."""
    out = []
    for run in sorted_runs(runs):
        if run.reference_xyz is not None:
            xyz = finite_positions(run.reference_xyz)
            if len(xyz):
                out.append((run, xyz))
    return out


def repeatability(runs: Sequence[SummaryRun]) -> list[RepeatabilityRow]:
    """Compare every run's reference path with the first run's, in space (not by time).

    The runs with a reference path are taken by ``recorded_at``; the first is the
    baseline. For each later run, every reference position's distance to the baseline's
    path (a polyline through its positions, point-to-segment) is measured
    (:func:`loceval.metrics.repeatability.path_deviations`); the median and the largest summarise
    how closely the path was re-driven. The duration difference tells whether it was
    driven at the same pace.

    Args:
        runs: the runs, in any order; those without ``reference_xyz`` (or with no finite
            position) are left out.

    Returns:
        The baseline's row first, then one row per later run with a path.
    """
    with_path = runs_with_path(runs)
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
    deviations = path_deviations(first_xyz, [xyz for _, xyz in later])
    for (run, _), deviation in zip(later, deviations, strict=True):  # one per run
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
                points=deviation.points,
                baseline=False,
                median_m=deviation.median_m,
                max_m=deviation.max_m,
                duration_s=run.duration_s,
                duration_diff_s=diff,
                timing=_timing(first, run),
            )
        )
    return rows


def _timing(first: SummaryRun, run: SummaryRun) -> RedriveTiming | None:
    """The re-drive timing of ``run`` against ``first`` when both carry their times."""
    t1, xyz1, t2, xyz2 = (
        first.reference_t_s,
        first.reference_xyz,
        run.reference_t_s,
        run.reference_xyz,
    )
    if t1 is None or xyz1 is None or t2 is None or xyz2 is None:
        return None
    if len(t1) != len(xyz1) or len(t2) != len(xyz2):
        return None
    try:
        return redrive_timing(t1, xyz1, t2, xyz2)
    except InputError:
        return None
