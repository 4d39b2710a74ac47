"""An evaluation against a baseline: each estimate and system against an earlier result.

The baseline is an earlier evaluation of the same systems: a loceval ``result.json`` (with
its ``errors.csv`` when at hand) or evo result zips (``evo_ape``/``evo_rpe
--save_results``); the front doors read it into a :class:`Baseline`
(``service.results.baseline``). Each estimate, and each system of trials, is compared with
the baseline's of the **same name**, on the RMSE of the ATE and of the RPE (translation),
as ``difference = current - baseline`` (negative: better now):

- **paired** where both keep per-pose errors at shared stamps (our ``errors.csv``, evo's
  ``error_array`` with ``timestamps``) of the same reference recording (a loceval baseline
  made against a reference of another SHA-256 never pairs: equal stamps of two recordings
  are not the same instants): the stamps are paired by nearest stamp within 10 ms
  (evo's tolerance) and the interval is the paired circular block bootstrap of
  :func:`loceval.assessment.comparison.compare_errors` (what both runs share cancels). RPE
  errors pair only when both were made with the same RPE pairs (delta, unit, all pairs):
  evo's RPE pairs, or loceval's with other options, are compared unpaired.
- **unpaired** otherwise: the MOVER combination (Zou & Donner 2008, "method of variance
  estimates recovery") of the two RMSEs' own 95 % intervals (each loceval's block
  bootstrap; an evo zip's RMSE bootstrapped here from its ``error_array``):
  ``[d - sqrt((c - l_c)^2 + (u_b - b)^2), d + sqrt((u_c - c)^2 + (b - l_b)^2)]``.
- **a system** against the baseline's system of the same name: over all trials of both
  (:func:`loceval.assessment.trials.compare_systems`: Hodges-Lehmann shift, Moses
  interval); against a baseline's single estimate of that name: the mean over trials
  minus the baseline's RMSE, the MOVER combination of the trials' t-interval and the
  baseline's interval (the baseline taken as exact when it has none).

Trials are compared only as their system: trial k now and trial k of the baseline are
different runs, and pairing their poses would leave out the spread from run to run.

The **verdict** is ``better`` (the interval wholly below 0), ``worse`` (wholly above),
``within_noise`` (it holds 0) or ``undetermined`` (no interval: too few trials, or neither
pairs nor intervals).

Result document::

    baseline: {label, kind: loceval | evo, source,
      comparisons: [{name, level: estimate | system, metric: ate_rmse | rpe_rmse, unit,
                     current, baseline, difference, interval: [low, high] | null,
                     paired: bool, n, method,
                     verdict: better | worse | within_noise | undetermined, summary}],
      notes: [str]}                           names without a counterpart, and why
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Final, Literal

import numpy as np

from loceval.assessment.trials import MetricOverTrials, compare_systems
from loceval.core.arrays import FloatArray, StampsNs
from loceval.errors import LocevalError

if TYPE_CHECKING:
    from loceval.evaluation import EstimateResult, EvaluationResult
    from loceval.readers.evo_result import ResultZip
    from loceval.results.document import ResultRead

__all__ = [
    "BASELINE_METRICS",
    "Baseline",
    "BaselineComparison",
    "BaselineDifference",
    "BaselineEntry",
    "BaselineSystem",
    "baseline_from_document",
    "baseline_from_evo",
    "compare_with_baseline",
    "mover_interval",
]

BASELINE_METRICS: Final[Mapping[str, str]] = {"ate_rmse": "ATE RMSE", "rpe_rmse": "RPE RMSE"}
"""The metrics compared with a baseline, by key, with their name in sentences."""

Verdict = Literal["better", "worse", "within_noise", "undetermined"]
_MAX_DT_S: Final = 0.01
_PAIRED: Final = "paired block bootstrap of the RMSE difference on the shared stamps"
_MOVER: Final = "unpaired: MOVER combination of the two RMSEs' 95 % intervals"


@dataclass(frozen=True, slots=True, eq=False)
class BaselineEntry:
    """One estimate of the baseline.

    Attributes:
        name: its name (the matching key).
        rmse: each metric's RMSE, by key (:data:`BASELINE_METRICS`).
        ci95: each metric's 95 % interval of the RMSE, when the baseline has one.
        series: each metric's per-pose errors ``(stamps_ns, errors)``, when kept.
        rpe_pairing: how its RPE pairs were made (``"1 m, consecutive"``), None: unknown.
        units: each metric's unit.
    """

    name: str
    rmse: Mapping[str, float]
    ci95: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    series: Mapping[str, tuple[StampsNs, FloatArray]] = field(default_factory=dict)
    rpe_pairing: str | None = None
    units: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, eq=False)
class BaselineSystem:
    """One system of the baseline: each metric's value per trial.

    Attributes:
        name: the system's name.
        values: each metric's per-trial values, by key.
        units: each metric's unit.
    """

    name: str
    values: Mapping[str, FloatArray]
    units: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, eq=False)
class Baseline:
    """An earlier result to compare with.

    Attributes:
        label: how reports name it (a file name, an evaluation id).
        kind: ``loceval`` (a result document) or ``evo`` (result zips).
        source: where it came from (a path as given, ``evaluation:<id>``).
        estimates: its estimates.
        systems: its systems of trials.
        notes: what reading it found (an evo zip of a rotation metric left out...).
        reference_sha256: the SHA-256 of the reference it was made against (None: unknown).
    """

    label: str
    kind: Literal["loceval", "evo"]
    source: str
    estimates: tuple[BaselineEntry, ...] = ()
    systems: tuple[BaselineSystem, ...] = ()
    notes: tuple[str, ...] = ()
    reference_sha256: str | None = None


@dataclass(frozen=True, slots=True)
class BaselineDifference:
    """One figure now against the baseline's.

    Attributes:
        name: the estimate's or system's name.
        level: ``estimate`` or ``system``.
        metric: the key (:data:`BASELINE_METRICS`).
        unit: the unit.
        current: the figure now (a system: its median over trials).
        baseline: the baseline's figure (a system: its median over trials).
        difference: the difference (see the module's docstring for each level).
        interval: its 95 % interval, or None.
        paired: whether the interval is a paired one.
        n: shared stamps (paired), or trials now (a system).
        method: how the interval is made, in words.
        verdict: ``better``, ``worse``, ``within_noise`` or ``undetermined``.
    """

    name: str
    level: Literal["estimate", "system"]
    metric: str
    unit: str
    current: float
    baseline: float
    difference: float
    interval: tuple[float, float] | None
    paired: bool
    n: int
    method: str
    verdict: Verdict

    @property
    def summary(self) -> str:
        """One sentence for the report."""
        label = BASELINE_METRICS.get(self.metric, self.metric)
        d = _fmt(self.difference, self.unit)
        words = {
            "better": "better than the baseline",
            "worse": "worse than the baseline",
            "within_noise": "within the noise of the baseline",
            "undetermined": "undetermined (no interval)",
        }[self.verdict]
        if self.interval is None:
            return f"{self.name}, {label}: {d} against the baseline, {words}."
        lo, hi = (_fmt(v, self.unit) for v in self.interval)
        kind = "paired" if self.paired else "unpaired"
        return f"{self.name}, {label}: {d} ({kind} 95 % interval {lo} to {hi}), {words}."

    def to_dict(self) -> dict[str, object]:
        """Return the document's block (see the module's docstring)."""
        return {
            "name": self.name,
            "level": self.level,
            "metric": self.metric,
            "unit": self.unit,
            "current": self.current,
            "baseline": self.baseline,
            "difference": self.difference,
            "interval": None if self.interval is None else list(self.interval),
            "paired": self.paired,
            "n": self.n,
            "method": self.method,
            "verdict": self.verdict,
            "summary": self.summary,
        }


@dataclass(frozen=True, slots=True)
class BaselineComparison:
    """The result against the baseline.

    Attributes:
        label: the baseline's label.
        kind: ``loceval`` or ``evo``.
        source: where the baseline came from.
        differences: each estimate's and system's figures against the baseline's.
        notes: names without a counterpart, and what reading the baseline found.
    """

    label: str
    kind: str
    source: str
    differences: tuple[BaselineDifference, ...]
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """Return the document's ``baseline`` object."""
        return {
            "label": self.label,
            "kind": self.kind,
            "source": self.source,
            "comparisons": [d.to_dict() for d in self.differences],
            "notes": list(self.notes),
        }


def _fmt(value: float, unit: str) -> str:
    if unit == "m" and abs(value) < 1.0:
        return f"{value * 100:+.1f} cm"
    if unit == "m":
        return f"{value:+.3f} m"
    return f"{value:+.3g}{'°' if unit == 'deg' else ' ' + unit}"


def _verdict(interval: tuple[float, float] | None) -> Verdict:
    if interval is None:
        return "undetermined"
    lo, hi = interval
    return "better" if hi < 0.0 else "worse" if lo > 0.0 else "within_noise"


def mover_interval(
    current: float,
    current_ci: tuple[float, float],
    baseline: float,
    baseline_ci: tuple[float, float],
) -> tuple[float, float]:
    """Return the MOVER 95 % interval of ``current - baseline`` from the two intervals.

    Zou & Donner (2008): ``L = d - sqrt((c - l_c)^2 + (u_b - b)^2)``,
    ``U = d + sqrt((u_c - c)^2 + (b - l_b)^2)``; for independent estimates.
    """
    d = current - baseline
    lo = d - math.hypot(current - current_ci[0], baseline_ci[1] - baseline)
    hi = d + math.hypot(current_ci[1] - current, baseline - baseline_ci[0])
    return lo, hi


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
    return _bootstrap_ci(getattr(e, key).values)


def _bootstrap_ci(errors: FloatArray) -> tuple[float, float] | None:
    from loceval.assessment.uncertainty import interval_stats  # noqa: PLC0415  (scipy)

    try:
        lo, hi = interval_stats(np.asarray(errors, dtype=np.float64)).ci95["rmse"]
    except LocevalError:
        return None
    return float(lo), float(hi)


def _paired(
    current: tuple[StampsNs, FloatArray],
    baseline: tuple[StampsNs, FloatArray],
    name: str,
    metric: str,
) -> tuple[float, tuple[float, float], int] | None:
    """Return ``(difference, interval, n)`` on the shared stamps, or None (too few)."""
    from loceval.assessment.comparison import ComparedMetric, compare_errors  # noqa: PLC0415
    from loceval.registration.stamps import match_nearest_seconds  # noqa: PLC0415

    t_c, e_c = np.asarray(current[0], np.int64), np.asarray(current[1], np.float64)
    t_b, e_b = np.asarray(baseline[0], np.int64), np.asarray(baseline[1], np.float64)
    keep = np.unique(t_c, return_index=True)[1]
    t_c, e_c = t_c[keep], e_c[keep]
    order = np.argsort(t_b, kind="stable")
    t_b, e_b = t_b[order], e_b[order]
    c_idx, b_idx = match_nearest_seconds(t_c, t_b, max_dt_s=_MAX_DT_S)
    first = np.unique(c_idx, return_index=True)[1]
    c_idx, b_idx = c_idx[first], b_idx[first]
    if c_idx.size < 8:
        return None
    ec, eb = e_c[c_idx], e_b[b_idx]
    if np.allclose(ec, eb, rtol=1e-9, atol=0.0):  # the same errors: no difference at all
        d = math.sqrt(float(np.mean(ec**2))) - math.sqrt(float(np.mean(eb**2)))
        return d, (d, d), int(c_idx.size)
    stamps = t_c[c_idx]
    found = compare_errors(
        stamps, ec, stamps, eb, a=name, b="baseline", metric=ComparedMetric(metric)
    )
    return found.difference, found.ci95, found.n_common


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
        paired = _paired((current_series.stamps_ns, current_series.values), series, e.name, metric)
        if paired is not None:
            d, interval, n = paired
            return BaselineDifference(
                e.name, "estimate", metric, unit, current, base, d, interval,
                paired=True, n=n, method=_PAIRED, verdict=_verdict(interval),
            )  # fmt: skip
    own = _own_ci(e, metric)
    theirs: tuple[float, float] | None = entry.ci95.get(metric)
    if theirs is None and series is not None:
        theirs = _bootstrap_ci(series[1])
    combined = None if own is None or theirs is None else mover_interval(current, own, base, theirs)
    return BaselineDifference(
        e.name, "estimate", metric, unit, current, base, current - base, combined,
        paired=False, n=len(current_series), method=_MOVER, verdict=_verdict(combined),
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
            method="over all trials of both: " + found.method, verdict=_verdict(found.interval),
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
        verdict=_verdict(interval),
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
            lo_hi = _bootstrap_ci(errors)  # no stamps: its own interval, for MOVER
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
