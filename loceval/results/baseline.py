"""An evaluation against a baseline: the comparison, and the baseline read from a result.

:func:`compare_with_baseline` compares each estimate and system of an evaluation with the
baseline's of the same name; :func:`baseline_from_document` and :func:`baseline_from_evo`
read a baseline from a loceval result document or from evo result zips. How each
difference, interval and verdict is made is said in :mod:`loceval.assessment.baseline`
(the types and the statistics); this module sits above the evaluation, whose results it
reads.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from loceval.assessment.baseline import (
    BASELINE_METRICS,
    MOVER_METHOD,
    PAIRED_METHOD,
    Baseline,
    BaselineComparison,
    BaselineDifference,
    BaselineEntry,
    BaselineSystem,
    baseline_verdict,
    bootstrap_rmse_ci,
    mover_interval,
    paired_difference,
)
from loceval.assessment.trial_comparison import compare_systems
from loceval.assessment.trials import MetricOverTrials
from loceval.core.arrays import FloatArray, StampsNs

if TYPE_CHECKING:
    from loceval.evaluation import EstimateResult, EvaluationResult
    from loceval.readers.evo_result import ResultZip
    from loceval.results.document import ResultRead

__all__ = ["SeriesOf", "baseline_from_document", "baseline_from_evo", "compare_with_baseline"]


def _rpe_pairing(result: EvaluationResult) -> str:
    cfg = result.config
    return (
        f"{cfg.rpe_delta:g} {cfg.rpe_unit.value}, {'all' if cfg.rpe_all_pairs else 'consecutive'}"
    )


def _own_ci(e: EstimateResult, metric: str) -> tuple[float, float] | None:
    """The estimate's 95 % interval of the RMSE (its assessment's, else bootstrapped here)."""
    key = "ate_translation" if metric == "ate_rmse" else "rpe_translation"
    found = None if e.assessment is None else e.assessment.intervals.get(key)
    if found is not None and "rmse" in found.ci95:
        lo, hi = found.ci95["rmse"]
        return float(lo), float(hi)
    return bootstrap_rmse_ci(getattr(e, key).values)


def _estimate_difference(
    e: EstimateResult, entry: BaselineEntry, metric: str, pairing: str
) -> BaselineDifference | None:
    current_series = e.ate_translation if metric == "ate_rmse" else e.rpe_translation
    if metric not in entry.rmse:
        return None
    current = current_series.stats.rmse
    base = entry.rmse[metric]
    unit = entry.units.get(metric, current_series.unit)
    if unit != current_series.unit:
        return None
    series = entry.series.get(metric)
    can_pair = series is not None and (metric == "ate_rmse" or entry.rpe_pairing == pairing)
    if can_pair and series is not None:
        paired = paired_difference(
            (current_series.stamps_ns, current_series.values), series, e.name, metric
        )
        if paired is not None:
            d, interval, n = paired
            return BaselineDifference(
                e.name, "estimate", metric, unit, current, base, d, interval,
                paired=True, n=n, method=PAIRED_METHOD, verdict=baseline_verdict(interval),
            )  # fmt: skip
    own = _own_ci(e, metric)
    theirs: tuple[float, float] | None = entry.ci95.get(metric)
    if theirs is None and series is not None:
        theirs = bootstrap_rmse_ci(series[1])
    combined = None if own is None or theirs is None else mover_interval(current, own, base, theirs)
    return BaselineDifference(
        e.name, "estimate", metric, unit, current, base, current - base, combined,
        paired=False, n=len(current_series), method=MOVER_METHOD,
        verdict=baseline_verdict(combined),
    )  # fmt: skip


def _system_difference(
    name: str, mine: MetricOverTrials, base: BaselineSystem | BaselineEntry, metric: str
) -> BaselineDifference | None:
    if isinstance(base, BaselineSystem):
        values = base.values.get(metric)
        if values is None or base.units.get(metric, mine.unit) != mine.unit:
            return None
        found = compare_systems(
            mine.values, values, a=name, b="baseline", metric=metric, unit=mine.unit
        )
        return BaselineDifference(
            name, "system", metric, mine.unit, mine.median, float(np.median(values)),
            found.difference, found.interval, paired=False, n=mine.n,
            method="over all trials of both: " + found.method,
            verdict=baseline_verdict(found.interval),
        )  # fmt: skip
    if metric not in base.rmse or base.units.get(metric, mine.unit) != mine.unit:
        return None
    value = base.rmse[metric]
    interval = None
    if mine.interval is not None:
        own = (mine.interval.low, mine.interval.high)
        theirs = base.ci95.get(metric, (value, value))
        interval = mover_interval(mine.mean, own, value, theirs)
    return BaselineDifference(
        name, "system", metric, mine.unit, mine.mean, value, mine.mean - value, interval,
        paired=False, n=mine.n,
        method="the mean over trials against one baseline run: MOVER combination of the "
        "trials' t-interval and the baseline's interval",
        verdict=baseline_verdict(interval),
    )  # fmt: skip


def compare_with_baseline(result: EvaluationResult, baseline: Baseline) -> BaselineComparison:
    """Compare each estimate and system of ``result`` with the baseline's of the same name.

    Args:
        result: the evaluation now.
        baseline: the earlier result.

    Returns:
        The differences with their intervals and verdicts, and notes on names without a
        counterpart (see the module's docstring).
    """
    entries = {b.name: b for b in baseline.estimates}
    systems = {s.name: s for s in baseline.systems}
    found: list[BaselineDifference] = []
    notes = list(baseline.notes)
    mine = _reference_sha256(result.inputs)
    if (
        baseline.reference_sha256 is not None
        and mine is not None
        and mine != baseline.reference_sha256
    ):
        notes.append(
            "The baseline was made against another reference recording (its SHA-256 "
            "differs), so no comparison with it is paired: the intervals are combined."
        )
        entries = {name: replace(e, series={}) for name, e in entries.items()}
    matched = _estimates_against(result, entries, found, notes)
    matched |= _systems_against(result, entries, systems, found, notes)
    unmatched = sorted({*entries, *systems} - matched - _trial_names(result))
    if unmatched:
        notes.append(
            f"The baseline's {', '.join(repr(n) for n in unmatched)} "
            f"{'has' if len(unmatched) == 1 else 'have'} no counterpart now."
        )
    return BaselineComparison(
        label=baseline.label,
        kind=baseline.kind,
        source=baseline.source,
        differences=tuple(found),
        notes=tuple(notes),
    )


def _reference_sha256(inputs: Sequence[Mapping[str, object]]) -> str | None:
    """The SHA-256 of the reference among an evaluation's inputs, or None."""
    for record in inputs:
        if record.get("role") == "reference" and isinstance(record.get("sha256"), str):
            return str(record["sha256"])
    return None


def _trial_names(result: EvaluationResult) -> set[str]:
    """The names of the trials now (a baseline's trial of the same name is no orphan)."""
    return {f.name for f in result.failed_trials} | {
        e.name for e in result.estimates if e.system is not None
    }


def _estimates_against(
    result: EvaluationResult,
    entries: Mapping[str, BaselineEntry],
    found: list[BaselineDifference],
    notes: list[str],
) -> set[str]:
    pairing = _rpe_pairing(result)
    matched: set[str] = set()
    for e in result.estimates:
        if e.system is not None:  # compared as its system, over all trials
            continue
        entry = entries.get(e.name)
        if entry is None:
            notes.append(f"{e.name!r} has no estimate of that name in the baseline.")
            continue
        matched.add(e.name)
        for metric in BASELINE_METRICS:
            difference = _estimate_difference(e, entry, metric, pairing)
            if difference is not None:
                found.append(difference)
    return matched


def _systems_against(
    result: EvaluationResult,
    entries: Mapping[str, BaselineEntry],
    systems: Mapping[str, BaselineSystem],
    found: list[BaselineDifference],
    notes: list[str],
) -> set[str]:
    matched: set[str] = set()
    for system in result.systems:
        base: BaselineSystem | BaselineEntry | None = systems.get(system.name) or entries.get(
            system.name
        )
        if base is None:
            notes.append(f"The system {system.name!r} has no counterpart in the baseline.")
            continue
        matched.add(system.name)
        for metric in BASELINE_METRICS:
            mine = system.metrics.get(metric)
            if mine is None:
                continue
            difference = _system_difference(system.name, mine, base, metric)
            if difference is not None:
                found.append(difference)
    return matched


def baseline_from_parts(
    *,
    label: str,
    kind: Literal["loceval", "evo"],
    source: str,
    estimates: Sequence[BaselineEntry] = (),
    systems: Sequence[BaselineSystem] = (),
    notes: Sequence[str] = (),
) -> Baseline:
    """Return a :class:`Baseline` (a convenience for readers that gather its parts)."""
    return Baseline(label, kind, source, tuple(estimates), tuple(systems), tuple(notes))


SeriesOf = Callable[[str, str], "tuple[StampsNs, FloatArray] | None"]
"""Called with an estimate's name and a metric key: its per-pose errors, or None."""


def _pairing_of(options: Mapping[str, Any]) -> str | None:
    delta, unit, every = (
        options.get("rpe_delta"),
        options.get("rpe_unit"),
        options.get("rpe_all_pairs"),
    )
    if not isinstance(delta, int | float) or not isinstance(unit, str):
        return None
    return f"{delta:g} {unit}, {'all' if every else 'consecutive'}"


def baseline_from_document(
    read: ResultRead, *, label: str, source: str, series_of: SeriesOf | None = None
) -> Baseline:
    """Return the baseline held by a loceval result document.

    Args:
        read: the document, read (:func:`loceval.results.document.read_result`).
        label: how reports name the baseline.
        source: where it came from.
        series_of: the per-pose errors of an estimate (from its ``errors.csv``), if at hand.

    Returns:
        Its estimates (RMSE, 95 % interval, per-pose errors) and systems (per-trial values).
    """
    options = _mapping_of(read.document.get("options"))
    pairing = _pairing_of(options)
    estimates = []
    for e in read.estimates:
        rmse: dict[str, float] = {}
        ci95: dict[str, tuple[float, float]] = {}
        series: dict[str, tuple[StampsNs, FloatArray]] = {}
        for metric, kind in (("ate_rmse", "ate"), ("rpe_rmse", "rpe")):
            value = e.rmse_m(kind)  # type: ignore[arg-type]
            if value is None:
                continue
            rmse[metric] = value
            block = e.block(kind)  # type: ignore[arg-type]
            written = None if block is None or block.ci95 is None else block.ci95.get("rmse")
            if isinstance(written, Sequence) and len(written) == 2:
                ci95[metric] = (float(written[0]), float(written[1]))
            found = None if series_of is None else series_of(e.label, metric)
            if found is not None and found[0].size:
                series[metric] = found
        estimates.append(
            BaselineEntry(e.label, rmse, ci95, series, pairing, dict.fromkeys(rmse, "m"))
        )
    systems = [
        BaselineSystem(
            s.name,
            {k: np.asarray(m.values, dtype=np.float64) for k, m in s.metrics.items() if m.values},
            {k: m.unit for k, m in s.metrics.items()},
        )
        for s in read.systems
    ]
    inputs = read.document.get("inputs")
    records = [i for i in inputs if isinstance(i, Mapping)] if isinstance(inputs, list) else []
    return Baseline(
        label,
        "loceval",
        source,
        tuple(estimates),
        tuple(systems),
        reference_sha256=_reference_sha256(records),
    )


def _mapping_of(value: object) -> Mapping[str, Any]:
    return value if isinstance(value, Mapping) else {}


def baseline_from_evo(
    zips: Sequence[tuple[str, ResultZip]], *, label: str, source: str
) -> Baseline:
    """Return the baseline held by evo result zips (one system and metric per zip).

    A zip of APE or RPE of the translation in metres (``trans_part``, ``point_distance``)
    gives its system's ATE or RPE RMSE and, with ``timestamps``, its per-pose errors
    (evo's RPE pairs are evo's own: compared unpaired). Other zips are noted and left out.

    Args:
        zips: ``(system name, zip)`` of each zip.
        label: how reports name the baseline.
        source: where it came from.
    """
    rmse: dict[str, dict[str, float]] = {}
    series: dict[str, dict[str, tuple[StampsNs, FloatArray]]] = {}
    ci95: dict[str, dict[str, tuple[float, float]]] = {}
    notes = []
    for name, result in zips:
        value = result.stats.get("rmse")
        if result.metric is None or not result.translation_m or value is None:
            notes.append(
                f"The evo result {result.path.name!r} ({result.title or 'no title'}) is no "
                "translation error in metres; it is left out of the baseline."
            )
            continue
        metric = "ate_rmse" if result.metric == "ape" else "rpe_rmse"
        rmse.setdefault(name, {})[metric] = value
        found = result.error_series()
        if found is not None:
            series.setdefault(name, {})[metric] = found
        elif (errors := result.arrays.get("error_array")) is not None and errors.size >= 8:
            lo_hi = bootstrap_rmse_ci(errors)  # no stamps: its own interval, for MOVER
            if lo_hi is not None:
                ci95.setdefault(name, {})[metric] = lo_hi
    estimates = tuple(
        BaselineEntry(
            name,
            values,
            ci95.get(name, {}),
            series.get(name, {}),
            "evo",  # evo's RPE pairs: never paired with loceval's
            dict.fromkeys(values, "m"),
        )
        for name, values in rmse.items()
    )
    return Baseline(label, "evo", source, estimates, (), tuple(notes))
