"""Trials: several runs of one system on one reference, summarised and compared.

Most localization systems are not deterministic, so a team runs each build several times.
Estimates that name the same **system** are its trials. Per system and per headline metric
(:data:`TRIAL_METRICS`: the RMSE of the ATE and of the RPE, translation and rotation) the
trials give one value each, and this module summarises those values:

- **median, mean, spread**: the sample standard deviation (``ddof=1``), min, max, the
  quartiles and their IQR (linear interpolation between order statistics);
- **the interval over trials** (``interval``): the 95 % Student-t interval of the mean,
  ``mean ± t(0.975, n-1) · s / sqrt(n)``, made when there are at least
  :data:`MIN_TRIALS_FOR_INTERVAL` (3) trials; with fewer the figures come without an
  interval and ``note`` says there are too few trials. The t-interval assumes trial RMSEs
  scatter roughly normally; the distribution-free companion is
- **the interval of the median** (``median_interval``): the order-statistic interval
  ``[x_(k), x_(n+1-k)]`` with the largest ``k`` whose binomial coverage
  ``1 - 2 P(Bin(n, 1/2) <= k - 1)`` is at least 95 % (its exact confidence is written);
  it exists from 6 trials on (with 5 the widest, min to max, covers only 93.75 %).

A trial that **failed** is counted and named in its system's ``failed`` list, never dropped:
an estimate whose reading or evaluation raised a loceval error (no overlap, a degenerate
alignment, an unreadable file), or one that tracked less of the reference's duration than
the evaluation's ``min_trial_coverage`` (tracking lost; too few matched poses). A failed
trial does not enter the system's figures and does not stop the other trials' evaluation.

**Systems are compared over all their trials**
(:func:`loceval.assessment.trial_comparison.compare_systems`): the two-sided
Mann-Whitney rank-sum test of the per-trial RMSEs (scipy, exact for small samples) and the
Hodges-Lehmann estimate of the shift ``A - B`` (the median of all pairwise differences)
with its distribution-free interval (Moses): the pairwise differences' order statistics
``[D_(k), D_(mn+1-k)]`` where ``k - 1`` is the largest ``u`` with ``P(U <= u) <= 2.5 %``
under the null distribution of the Mann-Whitney ``U`` (exact by counting for
``m * n <= 2500``, else the normal approximation). When even the most extreme ranking is
more likely than 5 % (fewer than 40 ways to rank the two groups: 3 trials against 4, say)
no 95 % interval exists and the verdict is ``too_few_trials``.

Result document (:meth:`loceval.evaluation.EvaluationResult.to_dict`, read back by
:mod:`loceval.results.document`)::

    estimates[k].system: str | null           the system the estimate is a trial of
    systems: [                                 one per system named, in first-seen order
      {name, trials: [estimate names],         the trials that entered the figures
       failed: [{name, code, reason}],         the trials that failed, counted and named
       n_trials, n_failed,
       metrics: {ate_rmse | rpe_rmse | ate_rot_rmse | rpe_rot_rmse:
         {unit, n, values: [per trial, in trial order], median, mean, std, min, max,
          q1, q3, iqr,
          interval: {low, high, level, method} | null,        t-interval of the mean
          median_interval: {low, high, level, method} | null, order statistics
          note: str | null}}}]                  why an interval is missing
    system_comparisons: [                      every two systems, per metric both have
      {a, b, metric, unit, difference (Hodges-Lehmann A - B), interval: [low, high] | null,
       confidence (exact coverage of the interval) | null, p_value, n_a, n_b,
       verdict: a_better | b_better | within_noise | too_few_trials, method, summary}]
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

import numpy as np

from loceval.core.arrays import FloatArray, StampsNs
from loceval.core.gaps import gap_threshold_ns
from loceval.errors import InputError
from loceval.metrics.pose_errors import ErrorSeries

__all__ = [
    "MIN_TRIALS_FOR_INTERVAL",
    "TRIAL_METRICS",
    "FailedTrial",
    "MetricOverTrials",
    "SystemTrials",
    "TrialFigures",
    "TrialInterval",
    "finite_values",
    "group_evaluated_trials",
    "group_trials",
    "mean_interval",
    "median_interval",
    "summarise_trials",
    "tracked_share",
    "trial_figures",
]

TRIAL_METRICS: Final[Mapping[str, str]] = {
    "ate_rmse": "ATE RMSE",
    "rpe_rmse": "RPE RMSE",
    "ate_rot_rmse": "ATE rotation RMSE",
    "rpe_rot_rmse": "RPE rotation RMSE",
}
"""The headline metrics summarised over trials, by key, with their name in sentences."""

MIN_TRIALS_FOR_INTERVAL: Final = 3
"""Fewest trials of a system for the t-interval of its mean."""

LEVEL: Final = 0.95
"""The confidence of every interval over trials."""

_T_METHOD: Final = "Student t interval of the mean over trials"
_ORDER_METHOD: Final = "order-statistic interval of the median (binomial, distribution-free)"


@dataclass(frozen=True, slots=True)
class TrialInterval:
    """An interval over trials.

    Attributes:
        low: lower end (the metric's unit).
        high: upper end.
        level: its confidence (exact coverage for order statistics, 0.95 for t).
        method: how it is made, in words.
    """

    low: float
    high: float
    level: float
    method: str

    def to_dict(self) -> dict[str, object]:
        """Return ``{"low", "high", "level", "method"}``."""
        return {"low": self.low, "high": self.high, "level": self.level, "method": self.method}


@dataclass(frozen=True, slots=True)
class FailedTrial:
    """A trial that gave no figures for its system.

    Attributes:
        name: the estimate's name.
        system: the system it is a trial of.
        code: why, as a code: a loceval error's code (``association.no_matches``,
            ``input.unreadable``...) or ``trial.tracking_lost`` (too little of the run
            tracked).
        reason: why, in one sentence.
    """

    name: str
    system: str
    code: str
    reason: str

    def to_dict(self) -> dict[str, object]:
        """Return ``{"name", "code", "reason"}``."""
        return {"name": self.name, "code": self.code, "reason": self.reason}


@dataclass(frozen=True, slots=True, eq=False)
class MetricOverTrials:
    """One metric of one system over its trials.

    Attributes:
        metric: the key (:data:`TRIAL_METRICS`).
        unit: ``m``, ``deg`` or ``%``.
        values: (n,) the value of each trial, in trial order.
        median: median over trials.
        mean: mean over trials.
        std: sample standard deviation (``ddof=1``; 0 for one trial).
        min: smallest.
        max: largest.
        q1: first quartile.
        q3: third quartile.
        interval: the 95 % t-interval of the mean (None: fewer than 3 trials).
        median_interval: the order-statistic interval of the median (None: fewer than 6).
        note: why an interval is missing, or None.
    """

    metric: str
    unit: str
    values: FloatArray
    median: float
    mean: float
    std: float
    min: float
    max: float
    q1: float
    q3: float
    interval: TrialInterval | None
    median_interval: TrialInterval | None
    note: str | None

    @property
    def n(self) -> int:
        """Return the number of trials."""
        return int(self.values.shape[0])

    @property
    def iqr(self) -> float:
        """Return the interquartile range."""
        return self.q3 - self.q1

    def to_dict(self) -> dict[str, object]:
        """Return the document's metric block (see the module's docstring)."""
        return {
            "unit": self.unit,
            "n": self.n,
            "values": [float(v) for v in self.values],
            "median": self.median,
            "mean": self.mean,
            "std": self.std,
            "min": self.min,
            "max": self.max,
            "q1": self.q1,
            "q3": self.q3,
            "iqr": self.iqr,
            "interval": None if self.interval is None else self.interval.to_dict(),
            "median_interval": None
            if self.median_interval is None
            else self.median_interval.to_dict(),
            "note": self.note,
        }


@dataclass(frozen=True, slots=True, eq=False)
class SystemTrials:
    """One system: its trials, the failed ones, and each metric over the trials.

    Attributes:
        name: the system's name.
        trials: the names of the trials that entered the figures, in order.
        failed: the trials that failed, in order.
        metrics: each metric every trial has (:data:`TRIAL_METRICS` keys), in that order.
    """

    name: str
    trials: tuple[str, ...]
    failed: tuple[FailedTrial, ...] = ()
    metrics: Mapping[str, MetricOverTrials] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        """Return the document's system block (see the module's docstring)."""
        return {
            "name": self.name,
            "trials": list(self.trials),
            "failed": [f.to_dict() for f in self.failed],
            "n_trials": len(self.trials),
            "n_failed": len(self.failed),
            "metrics": {key: m.to_dict() for key, m in self.metrics.items()},
        }


def finite_values(values: Sequence[float] | FloatArray, what: str) -> FloatArray:
    """Return one finite value per trial as a (n,) array.

    Raises:
        InputError: no values, a NaN or inf, or not 1-D; ``what`` names them.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or x.size == 0 or not np.isfinite(x).all():
        msg = f"{what}: give one finite value per trial (got {x.size} values, or NaN/inf)."
        raise InputError(msg)
    return x


def mean_interval(values: Sequence[float] | FloatArray) -> TrialInterval | None:
    """Return the 95 % Student-t interval of the mean, or None with fewer than 3 values.

    Args:
        values: (n,) one value per trial.
    """
    from scipy import stats  # noqa: PLC0415  (scipy loads on use)

    x = finite_values(values, "The interval of the mean")
    n = x.size
    if n < MIN_TRIALS_FOR_INTERVAL:
        return None
    half = float(stats.t.ppf(0.5 + LEVEL / 2, n - 1)) * float(x.std(ddof=1)) / math.sqrt(n)
    mean = float(x.mean())
    return TrialInterval(mean - half, mean + half, LEVEL, _T_METHOD)


def median_interval(values: Sequence[float] | FloatArray) -> TrialInterval | None:
    """Return the order-statistic interval of the median with coverage ≥ 95 %, or None.

    The interval ``[x_(k), x_(n+1-k)]`` covers the population median with probability
    ``1 - 2 P(Bin(n, 1/2) <= k - 1)`` whatever the distribution (continuous); ``k`` is the
    largest with coverage at least 95 %. None when no ``k`` reaches it (fewer than 6 values).

    Args:
        values: (n,) one value per trial.
    """
    from scipy import stats  # noqa: PLC0415

    x = np.sort(finite_values(values, "The interval of the median"))
    n = x.size
    k = np.arange(1, n // 2 + 1)
    coverage = 1.0 - 2.0 * stats.binom.cdf(k - 1, n, 0.5)
    ok = np.flatnonzero(coverage >= LEVEL - 1e-12)
    if ok.size == 0:
        return None
    best = int(ok[-1])
    kk = int(k[best])
    return TrialInterval(float(x[kk - 1]), float(x[n - kk]), float(coverage[best]), _ORDER_METHOD)


def summarise_trials(
    values: Sequence[float] | FloatArray, *, metric: str, unit: str
) -> MetricOverTrials:
    """Summarise one metric over a system's trials.

    Args:
        values: (n,) the metric of each trial, n ≥ 1, in trial order.
        metric: the key (:data:`TRIAL_METRICS`).
        unit: the values' unit.

    Returns:
        Median, mean, spread, the intervals over trials (see the module's docstring).

    Raises:
        InputError: no values, or a NaN/inf.
    """
    x = finite_values(values, f"{TRIAL_METRICS.get(metric, metric)} over trials")
    n = x.size
    q1, median, q3 = (float(q) for q in np.percentile(x, [25.0, 50.0, 75.0]))
    note = None
    if n < MIN_TRIALS_FOR_INTERVAL:
        note = (
            f"Too few trials for an interval: {n} "
            f"{'trial' if n == 1 else 'trials'}, and the interval over trials needs at least "
            f"{MIN_TRIALS_FOR_INTERVAL}."
        )
    return MetricOverTrials(
        metric=metric,
        unit=unit,
        values=x,
        median=median,
        mean=float(x.mean()),
        std=float(x.std(ddof=1)) if n > 1 else 0.0,
        min=float(x.min()),
        max=float(x.max()),
        q1=q1,
        q3=q3,
        interval=mean_interval(x),
        median_interval=median_interval(x),
        note=note,
    )


@dataclass(frozen=True, slots=True)
class TrialFigures:
    """One succeeded trial's headline figures, as the grouping takes them.

    Attributes:
        name: the estimate's name.
        system: its system.
        values: each metric it has, by key (:data:`TRIAL_METRICS`).
        units: each metric's unit, by key.
    """

    name: str
    system: str
    values: Mapping[str, float]
    units: Mapping[str, str]


def group_trials(
    figures: Sequence[TrialFigures], failed: Sequence[FailedTrial] = ()
) -> tuple[SystemTrials, ...]:
    """Group trials by system, in first-seen order, and summarise each metric.

    A metric is summarised when every succeeded trial of the system has it (a position-only
    trial has no rotation RMSE; the system then shows none rather than a subset).

    Args:
        figures: the succeeded trials.
        failed: the failed trials (each counted under its system).

    Returns:
        One :class:`SystemTrials` per system named by a trial or a failed trial.
    """
    order: list[str] = []
    for system in [f.system for f in figures] + [f.system for f in failed]:
        if system not in order:
            order.append(system)
    out = []
    for system in order:
        mine = [f for f in figures if f.system == system]
        metrics: dict[str, MetricOverTrials] = {}
        for key in TRIAL_METRICS:
            if mine and all(key in f.values for f in mine):
                metrics[key] = summarise_trials(
                    [f.values[key] for f in mine], metric=key, unit=mine[0].units[key]
                )
        out.append(
            SystemTrials(
                name=system,
                trials=tuple(f.name for f in mine),
                failed=tuple(f for f in failed if f.system == system),
                metrics=metrics,
            )
        )
    return tuple(out)


def tracked_share(reference_ns: StampsNs, matched_ns: StampsNs, *, min_gap_ns: int) -> float:
    """Return the share of the reference's duration a trial tracked, 0..1.

    The intervals between its matched stamps that are no gap (:func:`gap_threshold_ns` of
    the matched stamps, floored at ``min_gap_ns``) count as tracked; vectorised.

    Args:
        reference_ns: (N,) the reference's stamps.
        matched_ns: (M,) the trial's matched stamps (on the reference's clock), increasing.
        min_gap_ns: the evaluation's maximum gap, nanoseconds.
    """
    span = int(reference_ns[-1]) - int(reference_ns[0])
    if span <= 0 or matched_ns.shape[0] < 2:
        return 0.0
    steps = np.diff(matched_ns)
    limit = gap_threshold_ns(matched_ns, min_gap_ns=min_gap_ns)
    return min(1.0, float(steps[steps <= limit].sum()) / span)


def trial_figures(name: str, system: str, series: Mapping[str, ErrorSeries | None]) -> TrialFigures:
    """Return a trial's headline figures: the RMSE of each error series it has.

    Args:
        name: the estimate's name.
        system: its system.
        series: the error series of each metric key (None: the trial has none, e.g. no
            rotation for a position-only system).
    """
    values, units = {}, {}
    for key, found in series.items():
        if found is not None and len(found):
            values[key], units[key] = found.stats.rmse, found.unit
    return TrialFigures(name, system, values, units)


def group_evaluated_trials(
    trials: Sequence[tuple[TrialFigures, float]],
    failed: list[FailedTrial],
    *,
    min_coverage: float,
) -> tuple[SystemTrials, ...]:
    """Group evaluated trials; one that tracked less than ``min_coverage`` is a failed trial.

    Args:
        trials: each trial's figures and the share of the run it tracked
            (:func:`tracked_share`).
        failed: the trials that failed already; those that tracked too little are added.
        min_coverage: the least share of the run a trial must track.

    Returns:
        The systems (:func:`group_trials`).
    """
    counted = []
    for figures, coverage in trials:
        if coverage < min_coverage:
            failed.append(
                FailedTrial(
                    figures.name,
                    figures.system,
                    "trial.tracking_lost",
                    f"It tracked {coverage:.0%} of the reference's duration, less than the "
                    f"{min_coverage:.0%} a trial needs (tracking lost or too few matched "
                    f"poses); its figures are shown but not counted for {figures.system}.",
                )
            )
            continue
        counted.append(figures)
    return group_trials(counted, failed)
