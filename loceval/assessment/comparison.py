"""Is system A better than system B on this run, or is the difference noise?

Two estimates evaluated against the same reference are compared on the stamps both matched
(the intersection of their matched stamps), so both RMSEs summarise the same stretch of
the run. The interval of the difference ``RMSE_A - RMSE_B`` comes from a **paired** circular
block bootstrap: each resample takes the same blocks of stamps from both error series, so
what the two systems have in common (a hard corridor, a fast turn) cancels in the
difference instead of widening its interval. Block length and resampling are those of
:mod:`loceval.assessment.uncertainty`; the block length is the largest Politis-White length of the
two squared-error series and of their difference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from loceval.assessment.uncertainty import (
    DEFAULT_RESAMPLES,
    DEFAULT_SEED,
    BlockBootstrap,
    block_length,
    percentile_interval,
)
from loceval.core.arrays import FloatArray, StampsNs
from loceval.errors import InputError, MetricError
from loceval.metrics.pose_errors import ErrorSeries
from loceval.registration.stamps import match_nearest_seconds

__all__ = [
    "ComparedMetric",
    "Comparison",
    "ComparisonVerdict",
    "compare_error_series",
    "compare_errors",
    "compare_errors_nearest",
    "compare_runs",
    "compare_series",
]

_MIN_COMMON = 8


class ComparedMetric(StrEnum):
    """Which headline figure a comparison is about."""

    ATE_RMSE = "ate_rmse"
    RPE_RMSE = "rpe_rmse"

    @property
    def label(self) -> str:
        """The metric's short name in a sentence."""
        return "ATE" if self is ComparedMetric.ATE_RMSE else "RPE"


class ComparisonVerdict(StrEnum):
    """Which system the 95 % interval of the difference favours."""

    A_BETTER = "a_better"
    B_BETTER = "b_better"
    WITHIN_NOISE = "within_noise"


def _format(values: Sequence[float], unit: str) -> tuple[list[str], str]:
    """Return numbers for a sentence and their unit (centimetres for metres below 1 m)."""
    if unit == "m" and max(abs(v) for v in values) < 1.0:
        return [f"{v * 100:.1f}" for v in values], " cm"
    if unit == "m":
        return [f"{v:.3f}" for v in values], " m"
    suffix = "°" if unit == "deg" else f" {unit}"
    return [f"{v:.3g}" for v in values], suffix


@dataclass(frozen=True, slots=True)
class Comparison:
    """The difference of one RMSE between two systems on their common stamps.

    Attributes:
        a: name of the first system (A).
        b: name of the second system (B).
        metric: ATE or RPE RMSE.
        difference: ``RMSE_A - RMSE_B`` on the common stamps (negative: A is better).
        ci95: 95 % paired block-bootstrap interval of the difference.
        verdict: ``a_better`` when the whole interval is below 0, ``b_better`` when it is
            above 0, ``within_noise`` otherwise.
        rmse_a: A's RMSE on the common stamps.
        rmse_b: B's RMSE on the common stamps.
        n_common: number of common stamps.
        unit: unit of the errors ("m", "deg" or "%").
        block_length: block length of the resamples (errors).
    """

    a: str
    b: str
    metric: ComparedMetric
    difference: float
    ci95: tuple[float, float]
    verdict: ComparisonVerdict
    rmse_a: float
    rmse_b: float
    n_common: int
    unit: str
    block_length: int

    @property
    def summary(self) -> str:
        """One sentence for the report's verdict."""
        label = self.metric.label
        if self.verdict is ComparisonVerdict.WITHIN_NOISE:
            (d, lo, hi), unit = _format([self.difference, *self.ci95], self.unit)
            return (
                f"{self.a}'s and {self.b}'s {label} differ by {d}{unit} (95 % interval "
                f"{lo} to {hi}{unit}): the difference is within the noise."
            )
        better, worse = (
            (self.a, self.b)
            if self.verdict is ComparisonVerdict.A_BETTER
            else (
                self.b,
                self.a,
            )
        )
        magnitudes = sorted(abs(v) for v in self.ci95)
        (d, lo, hi), unit = _format([abs(self.difference), *magnitudes], self.unit)
        return (
            f"{better}'s {label} is lower than {worse}'s: difference {d}{unit}, "
            f"95 % interval {lo}-{hi}{unit}."
        )

    def to_dict(self) -> dict[str, object]:
        """Return the JSON contract ``{"a", "b", "metric", "difference", "ci95", "verdict"}``."""
        return {
            "a": self.a,
            "b": self.b,
            "metric": self.metric.value,
            "difference": self.difference,
            "ci95": list(self.ci95),
            "verdict": self.verdict.value,
        }


def _verdict(lo: float, hi: float) -> ComparisonVerdict:
    """Return A better, B better or within the noise from the 95 % interval of A - B."""
    if hi < 0.0:
        return ComparisonVerdict.A_BETTER
    if lo > 0.0:
        return ComparisonVerdict.B_BETTER
    return ComparisonVerdict.WITHIN_NOISE


def _from_bootstrap(
    diffs: FloatArray,
    value_a: float,
    value_b: float,
    *,
    a: str,
    b: str,
    metric: ComparedMetric,
    n_common: int,
    unit: str,
    block: int,
) -> Comparison:
    """Return the comparison of A's and B's figures from the resampled differences A* - B*."""
    lo, hi = percentile_interval(diffs)
    return Comparison(
        a=a,
        b=b,
        metric=metric,
        difference=value_a - value_b,
        ci95=(lo, hi),
        verdict=_verdict(lo, hi),
        rmse_a=value_a,
        rmse_b=value_b,
        n_common=n_common,
        unit=unit,
        block_length=block,
    )


def compare_errors(
    stamps_a_ns: StampsNs,
    errors_a: FloatArray,
    stamps_b_ns: StampsNs,
    errors_b: FloatArray,
    *,
    a: str,
    b: str,
    metric: ComparedMetric,
    unit: str = "m",
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> Comparison:
    """Compare two error series' RMSE on their common stamps with a paired block bootstrap.

    Args:
        stamps_a_ns: (N_A,) stamps of A's errors, unique (for RPE the pair's first stamp,
            which identifies the same pair in both only when pairs are defined on the
            reference).
        errors_a: (N_A,) A's errors, in time order.
        stamps_b_ns: (N_B,) stamps of B's errors, unique.
        errors_b: (N_B,) B's errors, in time order.
        a: A's name in sentences.
        b: B's name in sentences.
        metric: which RMSE this is.
        unit: unit of the errors ("m", "deg" or "%").
        resamples: bootstrap resamples (≥ 100).
        seed: bootstrap seed.

    Returns:
        The difference A - B, its interval and the verdict.

    Raises:
        InputError: arrays of different lengths, repeated stamps, or fewer than 100
            resamples.
        MetricError: fewer than 8 common stamps.
    """
    arrays = []
    for name, stamps, errors in ((a, stamps_a_ns, errors_a), (b, stamps_b_ns, errors_b)):
        t = np.asarray(stamps, dtype=np.int64)
        e = np.asarray(errors, dtype=np.float64)
        if t.shape != e.shape or t.ndim != 1:
            msg = (
                f"{name!r}: the stamps {t.shape!r} and errors {e.shape!r} of a comparison "
                "must be 1-D arrays of the same length."
            )
            raise InputError(msg)
        if np.unique(t).size != t.size:
            msg = (
                f"{name!r}: the error series repeats stamps, so they cannot pair errors with "
                "the other system's; compare series with one error per stamp."
            )
            raise InputError(msg)
        if not np.isfinite(e).all():
            msg = f"{name!r}: the error series contains NaN or inf; drop unmatched poses."
            raise InputError(msg)
        arrays.append((t, e))
    (t_a, e_a), (t_b, e_b) = arrays
    common, idx_a, idx_b = np.intersect1d(t_a, t_b, assume_unique=True, return_indices=True)
    if common.size < _MIN_COMMON:
        msg = (
            f"{a!r} and {b!r} share only {common.size} matched stamps (at least "
            f"{_MIN_COMMON} needed); compare systems evaluated over the same stretch of the run."
        )
        raise MetricError(msg)
    sq_a, sq_b = e_a[idx_a] ** 2, e_b[idx_b] ** 2
    block = max(block_length(s) for s in (sq_a, sq_b, sq_a - sq_b))
    boot = BlockBootstrap.draw(common.size, block, resamples=resamples, seed=seed)
    means = boot.means(np.vstack([sq_a, sq_b]))
    diffs = np.sqrt(means[0]) - np.sqrt(means[1])
    rmse_a, rmse_b = math.sqrt(float(sq_a.mean())), math.sqrt(float(sq_b.mean()))
    return _from_bootstrap(
        diffs,
        rmse_a,
        rmse_b,
        a=a,
        b=b,
        metric=metric,
        n_common=int(common.size),
        unit=unit,
        block=boot.block,
    )


def compare_errors_nearest(
    stamps_a_ns: StampsNs,
    errors_a: FloatArray,
    stamps_b_ns: StampsNs,
    errors_b: FloatArray,
    *,
    a: str,
    b: str,
    metric: ComparedMetric,
    unit: str = "m",
    max_dt_s: float = 0.01,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> Comparison:
    """Compare two error series written by different tools, pairing instants by nearest stamp.

    Two tools (evo and loceval, or two evo runs) evaluating systems over the same run stamp
    their errors with their own matched poses, which need not coincide to the nanosecond:
    each of A's instants takes B's error at the nearest stamp within ``max_dt_s`` (evo's
    default tolerance, 10 ms; float seconds as evo matches), one B error per A instant,
    and the RMSEs are compared on those pairs with :func:`compare_errors`.

    Args:
        stamps_a_ns: (N_A,) stamps of A's errors, sorted.
        errors_a: (N_A,) A's errors.
        stamps_b_ns: (N_B,) stamps of B's errors, sorted.
        errors_b: (N_B,) B's errors.
        a: A's name in sentences.
        b: B's name in sentences.
        metric: which RMSE this is.
        unit: unit of the errors ("m", "deg" or "%").
        max_dt_s: the largest stamp difference of a pair, seconds.
        resamples: bootstrap resamples (≥ 100).
        seed: bootstrap seed.

    Returns:
        The difference A - B on the paired instants, its interval and the verdict.

    Raises:
        InputError: see :func:`compare_errors`.
        MetricError: fewer than 8 paired instants, or the same errors at every instant
            (one result given twice: nothing to compare).
    """
    t_a = np.asarray(stamps_a_ns, dtype=np.int64)
    t_b = np.asarray(stamps_b_ns, dtype=np.int64)
    e_a = np.asarray(errors_a, dtype=np.float64)
    e_b = np.asarray(errors_b, dtype=np.float64)
    if t_a.shape != e_a.shape or t_b.shape != e_b.shape:
        msg = f"{a!r} or {b!r}: stamps and errors of a comparison must be as long."
        raise InputError(msg)
    keep_a = np.unique(t_a, return_index=True)[1]
    t_a, e_a = t_a[keep_a], e_a[keep_a]
    order_b = np.argsort(t_b, kind="stable")
    t_b, e_b = t_b[order_b], e_b[order_b]
    a_idx, b_idx = match_nearest_seconds(t_a, t_b, max_dt_s=max_dt_s)
    first = np.unique(a_idx, return_index=True)[1]  # one B error per A instant
    a_idx, b_idx = a_idx[first], b_idx[first]
    if a_idx.size == t_a.size and np.allclose(e_a[a_idx], e_b[b_idx], rtol=1e-9, atol=0.0):
        msg = (
            f"{a!r} and {b!r} have the same errors at every instant (equal within 1e-9): "
            "the same result given twice, nothing to compare."
        )
        raise MetricError(msg)
    return compare_errors(
        t_a[a_idx], e_a[a_idx], t_a[a_idx], e_b[b_idx], a=a, b=b, metric=metric, unit=unit,
        resamples=resamples, seed=seed,
    )  # fmt: skip


def compare_error_series(
    series_a: ErrorSeries,
    series_b: ErrorSeries,
    *,
    a: str,
    b: str,
    metric: ComparedMetric,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> Comparison:
    """Compare two error series (in the unit of ``series_a``) with :func:`compare_errors`.

    Args:
        series_a: A's errors.
        series_b: B's errors, against the same reference.
        a: A's name in sentences.
        b: B's name in sentences.
        metric: which RMSE the series give.
        resamples: bootstrap resamples (≥ 100).
        seed: bootstrap seed.

    Returns:
        The difference A - B, its interval and the verdict.

    Raises:
        InputError: see :func:`compare_errors`.
        MetricError: see :func:`compare_errors`.
    """
    return compare_errors(
        series_a.stamps_ns,
        series_a.values,
        series_b.stamps_ns,
        series_b.values,
        a=a,
        b=b,
        metric=metric,
        unit=series_a.unit,
        resamples=resamples,
        seed=seed,
    )


def compare_series(
    named: Sequence[tuple[str, ErrorSeries]],
    *,
    metric: ComparedMetric,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> list[Comparison]:
    """Compare every pair of systems in the order given (A before B).

    Args:
        named: ``(name, errors)`` of each system, all against the same reference, all in
            the same unit.
        metric: which RMSE the series give.
        resamples: bootstrap resamples (≥ 100).
        seed: bootstrap seed (the same for every pair).

    Returns:
        ``len(named) * (len(named) - 1) / 2`` comparisons: (0, 1), (0, 2), ..., (1, 2), ...

    Raises:
        InputError: series in different units, or see :func:`compare_errors`.
        MetricError: see :func:`compare_errors`.
    """
    units = {series.unit for _, series in named}
    if len(units) > 1:
        msg = f"Comparisons need errors in one unit, got {sorted(units)!r}; use one RPE unit."
        raise InputError(msg, option="rpe_unit")
    return [
        compare_error_series(sa, sb, a=na, b=nb, metric=metric, resamples=resamples, seed=seed)
        for i, (na, sa) in enumerate(named)
        for nb, sb in named[i + 1 :]
    ]


def compare_runs(
    values_a: Sequence[float] | FloatArray,
    values_b: Sequence[float] | FloatArray,
    *,
    a: str,
    b: str,
    metric: ComparedMetric,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> Comparison:
    """Compare two systems' mean RMSE over runs that share no stamps (a schedule's runs).

    Each system's per-run RMSEs (in run order) are resampled on their own, an **unpaired**
    circular block bootstrap (block length by Politis-White over the run sequence, so a
    slow trend across runs is kept in blocks), and the interval of ``mean_A* - mean_B*`` is
    the percentile interval of the resampled differences. Runs of different dates are
    different data, so nothing pairs them, and the interval is wider than a paired one.

    Args:
        values_a: (K_A,) A's RMSE per run, metres, in run order.
        values_b: (K_B,) B's RMSE per run, metres, in run order.
        a: A's name in sentences.
        b: B's name in sentences.
        metric: which RMSE the values are.
        resamples: bootstrap resamples (≥ 100).
        seed: bootstrap seed (B's resamples use ``seed + 1``).

    Returns:
        The difference of the mean RMSEs, its interval and the verdict (``n_common`` 0: the
        runs share no stamps).

    Raises:
        InputError: fewer than 8 runs of a system, NaN/inf, or fewer than 100 resamples.
    """
    boots = []
    arrays = []
    for name, values, offset in ((a, values_a, 0), (b, values_b, 1)):
        x = np.asarray(values, dtype=np.float64)
        if x.ndim != 1 or x.size < _MIN_COMMON or not np.isfinite(x).all():
            msg = (
                f"{name!r} has {x.size} finite per-run figures, and a comparison across runs "
                f"needs at least {_MIN_COMMON}; compare again after more runs."
            )
            raise InputError(msg)
        block = block_length(x)
        boots.append(
            BlockBootstrap.draw(
                x.size, block, resamples=resamples, seed=seed + offset, cap_blocks=False
            )
        )
        arrays.append(x)
    diffs = boots[0].means(arrays[0]) - boots[1].means(arrays[1])
    return _from_bootstrap(
        diffs,
        float(arrays[0].mean()),
        float(arrays[1].mean()),
        a=a,
        b=b,
        metric=metric,
        n_common=0,
        unit="m",
        block=max(boot.block for boot in boots),
    )
