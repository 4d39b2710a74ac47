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

**Systems are compared over all their trials** (:func:`compare_systems`): the two-sided
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

from loceval.core.arrays import FloatArray
from loceval.errors import InputError

__all__ = [
    "MIN_TRIALS_FOR_INTERVAL",
    "TRIAL_METRICS",
    "FailedTrial",
    "MetricOverTrials",
    "SystemComparison",
    "SystemTrials",
    "TrialFigures",
    "TrialInterval",
    "compare_all_systems",
    "compare_systems",
    "group_trials",
    "mean_interval",
    "median_interval",
    "summarise_trials",
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
_MOSES_METHOD: Final = (
    "Mann-Whitney rank-sum test of the per-trial RMSEs; Hodges-Lehmann shift with its "
    "Moses interval"
)
_EXACT_LIMIT: Final = 2500
"""Largest ``m * n`` whose Mann-Whitney null distribution is counted exactly."""


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


def _finite_values(values: Sequence[float] | FloatArray, what: str) -> FloatArray:
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

    x = _finite_values(values, "The interval of the mean")
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

    x = np.sort(_finite_values(values, "The interval of the median"))
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
    x = _finite_values(values, f"{TRIAL_METRICS.get(metric, metric)} over trials")
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
class SystemComparison:
    """Two systems compared over all their trials on one metric.

    Attributes:
        a: system A.
        b: system B.
        metric: the key (:data:`TRIAL_METRICS`).
        unit: the metric's unit.
        difference: Hodges-Lehmann shift ``A - B`` (median of the pairwise differences of
            per-trial values; negative: A lower, better).
        interval: its distribution-free (Moses) interval, or None (too few trials).
        confidence: the interval's exact coverage (≥ 0.95), or None.
        p_value: two-sided Mann-Whitney p-value.
        n_a: A's trials.
        n_b: B's trials.
        verdict: ``a_better`` (interval below 0), ``b_better`` (above 0), ``within_noise``
            or ``too_few_trials`` (no 95 % interval exists for these counts).
        method: how it is made, in words.
    """

    a: str
    b: str
    metric: str
    unit: str
    difference: float
    interval: tuple[float, float] | None
    confidence: float | None
    p_value: float
    n_a: int
    n_b: int
    verdict: str
    method: str = _MOSES_METHOD

    @property
    def summary(self) -> str:
        """One sentence for the report."""
        label = TRIAL_METRICS.get(self.metric, self.metric)
        d = _fmt(self.difference, self.unit)
        trials = f"{self.n_a} against {self.n_b} trials"
        if self.interval is None:
            return (
                f"{self.a} vs {self.b}, {label}: median shift {d} over {trials}, too few "
                "trials for a 95 % interval."
            )
        lo, hi = (_fmt(v, self.unit) for v in self.interval)
        if self.verdict == "within_noise":
            return (
                f"{self.a} vs {self.b}, {label}: median shift {d} (interval {lo} to {hi}, "
                f"{trials}, p = {self.p_value:.3g}): within the noise."
            )
        better, worse = (self.a, self.b) if self.verdict == "a_better" else (self.b, self.a)
        return (
            f"{better}'s {label} is lower than {worse}'s over {trials}: shift {d} "
            f"(interval {lo} to {hi}, p = {self.p_value:.3g})."
        )

    def to_dict(self) -> dict[str, object]:
        """Return the document's comparison block (see the module's docstring)."""
        return {
            "a": self.a,
            "b": self.b,
            "metric": self.metric,
            "unit": self.unit,
            "difference": self.difference,
            "interval": None if self.interval is None else list(self.interval),
            "confidence": self.confidence,
            "p_value": self.p_value,
            "n_a": self.n_a,
            "n_b": self.n_b,
            "verdict": self.verdict,
            "method": self.method,
            "summary": self.summary,
        }


def _fmt(value: float, unit: str) -> str:
    if unit == "m" and abs(value) < 1.0:
        return f"{value * 100:+.1f} cm"
    if unit == "m":
        return f"{value:+.3f} m"
    return f"{value:+.3g}{'°' if unit == 'deg' else ' ' + unit}"


def _u_null_cdf(m: int, n: int) -> FloatArray:
    """Return ``P(U <= u)`` for ``u = 0..m*n`` under the null (no ties), by counting.

    The number of rankings with ``U = u`` is the coefficient of ``q^u`` in the Gaussian
    binomial ``[m+n choose m]_q``; it is built by the recurrence
    ``c(i, j) = c(i-1, j) shifted by j + c(i, j-1)`` over the table of (i, j), each cell a
    polynomial (array) in ``u``: ``O(m n · m n)`` additions, small for trials.
    """
    size = m * n + 1
    prev = [np.zeros(size) for _ in range(n + 1)]  # row i-1 (i = 0: only U = 0)
    for j in range(n + 1):
        prev[j][0] = 1.0
    for _ in range(1, m + 1):
        row = [np.zeros(size) for _ in range(n + 1)]
        row[0][0] = 1.0
        for j in range(1, n + 1):
            row[j] = row[j - 1].copy()
            row[j][j:] += prev[j][: size - j]
        prev = row
    counts = prev[n]
    cdf: FloatArray = np.cumsum(counts) / counts.sum()
    return cdf


def _moses_rank(m: int, n: int) -> tuple[int, float] | None:
    """Return ``(k, confidence)`` of the Moses interval ``[D_(k), D_(mn+1-k)]``, or None."""
    alpha_half = (1.0 - LEVEL) / 2
    if m * n <= _EXACT_LIMIT:
        cdf = _u_null_cdf(m, n)
        ok = np.flatnonzero(cdf <= alpha_half + 1e-12)
        if ok.size == 0:
            return None
        u = int(ok[-1])  # P(U <= u) <= 2.5 %: k - 1 = u
        return u + 1, float(1.0 - 2.0 * cdf[u])
    from scipy import stats  # noqa: PLC0415

    z = float(stats.norm.ppf(1.0 - alpha_half))
    k = math.floor(m * n / 2 - z * math.sqrt(m * n * (m + n + 1) / 12.0))
    return (k, LEVEL) if k >= 1 else None


def compare_systems(
    values_a: Sequence[float] | FloatArray,
    values_b: Sequence[float] | FloatArray,
    *,
    a: str,
    b: str,
    metric: str,
    unit: str,
) -> SystemComparison:
    """Compare two systems over all their trials (see the module's docstring).

    Args:
        values_a: (m,) A's value per trial.
        values_b: (n,) B's value per trial.
        a: A's name.
        b: B's name.
        metric: the key (:data:`TRIAL_METRICS`).
        unit: the values' unit.

    Returns:
        The Hodges-Lehmann shift A - B, its Moses interval, the rank-sum p-value, a verdict.

    Raises:
        InputError: a system without trials, or NaN/inf.
    """
    from scipy import stats  # noqa: PLC0415

    x = _finite_values(values_a, f"{a!r}'s {metric}")
    y = _finite_values(values_b, f"{b!r}'s {metric}")
    m, n = x.size, y.size
    diffs = np.sort((x[:, None] - y[None, :]).ravel())
    shift = float(np.median(diffs))
    if m * n == 1 or (np.ptp(np.concatenate([x, y])) == 0.0):
        p_value = 1.0
    else:
        p_value = float(stats.mannwhitneyu(x, y, alternative="two-sided").pvalue)
    rank = _moses_rank(m, n)
    if rank is None:
        return SystemComparison(
            a, b, metric, unit, shift, None, None, p_value, m, n, "too_few_trials"
        )
    k, confidence = rank
    lo, hi = float(diffs[k - 1]), float(diffs[m * n - k])
    verdict = "a_better" if hi < 0.0 else "b_better" if lo > 0.0 else "within_noise"
    return SystemComparison(a, b, metric, unit, shift, (lo, hi), confidence, p_value, m, n, verdict)


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


def compare_all_systems(systems: Sequence[SystemTrials]) -> tuple[SystemComparison, ...]:
    """Compare every two systems (A before B, in order) on each metric both have in one unit."""
    found = []
    for i, sa in enumerate(systems):
        for sb in systems[i + 1 :]:
            for key, ma in sa.metrics.items():
                mb = sb.metrics.get(key)
                if mb is None or mb.unit != ma.unit:
                    continue
                found.append(
                    compare_systems(
                        ma.values, mb.values, a=sa.name, b=sb.name, metric=key, unit=ma.unit
                    )
                )
    return tuple(found)
