"""Systems compared over all their trials: a rank-sum test and the shift's interval.

See :mod:`loceval.assessment.trials` for the figures of one system over its trials. Two
systems are compared on the per-trial values of one metric with the two-sided
Mann-Whitney rank-sum test (scipy, exact for small samples) and the Hodges-Lehmann estimate
of the shift ``A - B`` (the median of all pairwise differences) with its distribution-free
interval (Moses): the pairwise differences' order statistics ``[D_(k), D_(mn+1-k)]`` where
``k - 1`` is the largest ``u`` with ``P(U <= u) <= 2.5 %`` under the null distribution of
the Mann-Whitney ``U`` (exact by counting for ``m * n <= 2500``, else the normal
approximation). When even the most extreme ranking is more likely than 5 % (fewer than 40
ways to rank the two groups: 3 trials against 4, say) no 95 % interval exists and the
verdict is ``too_few_trials``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np

from loceval.assessment.trials import LEVEL, TRIAL_METRICS, finite_values
from loceval.core.arrays import FloatArray
from loceval.core.quantities import signed_difference

if TYPE_CHECKING:
    from loceval.assessment.trials import SystemTrials

__all__ = ["SystemComparison", "compare_all_systems", "compare_systems"]

_MOSES_METHOD: Final = (
    "Mann-Whitney rank-sum test of the per-trial RMSEs; Hodges-Lehmann shift with its "
    "Moses interval"
)
_EXACT_LIMIT: Final = 2500
"""Largest ``m * n`` whose Mann-Whitney null distribution is counted exactly."""


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
        d = signed_difference(self.difference, self.unit)
        trials = f"{self.n_a} against {self.n_b} trials"
        if self.interval is None:
            return (
                f"{self.a} vs {self.b}, {label}: median shift {d} over {trials}, too few "
                "trials for a 95 % interval."
            )
        lo, hi = (signed_difference(v, self.unit) for v in self.interval)
        if self.verdict == "within_noise":
            return (
                f"{self.a} vs {self.b}, {label}: median shift {d} (interval {lo} to {hi}, "
                f"{trials}, p = {self.p_value:.3g}): within the noise."
            )
        better, worse = (self.a, self.b) if self.verdict == "a_better" else (self.b, self.a)
        low, high = sorted(abs(v) for v in self.interval)
        by, lo, hi = (
            signed_difference(v, self.unit).lstrip("+") for v in (abs(self.difference), low, high)
        )
        return (
            f"{better}'s {label} is lower than {worse}'s by {by} over {trials} "
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

    x = finite_values(values_a, f"{a!r}'s {metric}")
    y = finite_values(values_b, f"{b!r}'s {metric}")
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
