"""Time the block-bootstrap intervals, a paired comparison and NEES on 50,000 matched poses.

Run by hand: ``.venv/bin/python -m benchmarks.uncertainty [--repeat N]``.
Target on a 2-core machine: ``interval_stats`` (RMSE, mean, median, three shares within,
500 resamples, automatic block length) on 50,000 errors under 0.5 s.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np
from scipy.signal import lfilter

from loceval.comparison import ComparedMetric, compare_errors
from loceval.consistency import check_consistency
from loceval.uncertainty import interval_stats

N = 50_000
TARGET_S = 0.5


def ar1_norms(rng: np.random.Generator, phi: float, sigma: float) -> np.ndarray:
    """Return N norms of 3-D AR(1) errors (per-axis standard deviation sigma)."""
    noise = rng.normal(0.0, sigma * np.sqrt(1.0 - phi**2), (N, 3))
    return np.linalg.norm(lfilter([1.0], [1.0, -phi], noise, axis=0), axis=1)


def timed(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Return the median and minimum wall time of ``fn``."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), min(times)


def main() -> int:
    """Time each case and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    opts = parser.parse_args()
    rng = np.random.default_rng(7)
    correlated = ar1_norms(rng, 0.95, 0.03)
    white = np.linalg.norm(rng.normal(0.0, 0.03, (N, 3)), axis=1)
    other = ar1_norms(rng, 0.95, 0.035)
    stamps = np.arange(N, dtype=np.int64) * 20_000_000
    cov = np.broadcast_to(np.diag([0.01, 0.01, 0.02]), (N, 3, 3))
    errors_xyz = rng.normal(0.0, 0.1, (N, 3))
    thresholds = (0.05, 0.10, 0.20)

    def intervals(values: np.ndarray) -> Callable[[], object]:
        return lambda: interval_stats(values, thresholds_m=thresholds)

    def paired() -> object:
        return compare_errors(
            stamps, correlated, stamps, other, a="A", b="B", metric=ComparedMetric.ATE_RMSE
        )

    cases: list[tuple[str, Callable[[], object], float | None]] = [
        ("interval_stats, AR(1) phi=0.95", intervals(correlated), TARGET_S),
        ("interval_stats, white errors", intervals(white), TARGET_S),
        ("compare_errors (paired)", paired, None),
        ("check_consistency (NEES)", lambda: check_consistency(errors_xyz, cov), None),
    ]
    print(f"{N} matched poses, median / min of {opts.repeat} runs")
    for name, fn, target in cases:
        med, best = timed(fn, opts.repeat)
        verdict = "" if target is None else f"< {target} s {'ok' if med < target else 'MISSED'}"
        print(f"{name:<32} {med:>7.3f} s {best:>7.3f} s  {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
