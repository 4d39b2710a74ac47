"""Time the block-bootstrap intervals, a paired comparison and NEES on 50,000 matched poses.

Run by hand: ``.venv/bin/python -m benchmarks.uncertainty [--repeat N]``.
Target on a 2-core machine: ``interval_stats`` (RMSE, mean, median, three shares within,
500 resamples, automatic block length) on 50,000 errors under 0.5 s; and what the intervals
add to a whole evaluation of 50,000 matched poses (``evaluate`` minus ``evaluate`` with
``no_ci``: ATE and RPE translation and rotation intervals and the tolerance verdict).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np
from scipy.signal import lfilter

from loceval.assessment.comparison import ComparedMetric, compare_errors
from loceval.assessment.consistency import check_consistency
from loceval.assessment.uncertainty import interval_stats
from loceval.evaluation import EvaluationConfig, Tolerance, evaluate
from loceval.trajectory import Trajectory

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

    t = np.arange(N) * 0.02
    truth = Trajectory(
        (t * 1e9).astype(np.int64),
        np.stack([np.cos(0.05 * t) * 10, np.sin(0.05 * t) * 10, 0.1 * np.sin(t)], axis=1),
        np.tile([0.0, 0.0, 0.0, 1.0], (N, 1)),
    )
    noise = lfilter([1.0], [1.0, -0.95], rng.normal(0.0, 0.01, (N, 3)), axis=0)
    estimate = Trajectory(truth.stamps_ns, truth.positions_xyz + noise, truth.quat_xyzw)
    with_ci = EvaluationConfig(tolerance=Tolerance(0.10, 0.95))
    no_ci = EvaluationConfig(tolerance=Tolerance(0.10, 0.95), no_ci=True)
    evaluate(truth, [estimate], with_ci)  # warm up: imports scipy once

    cases: list[tuple[str, Callable[[], object], float | None]] = [
        ("interval_stats, AR(1) phi=0.95", intervals(correlated), TARGET_S),
        ("interval_stats, white errors", intervals(white), TARGET_S),
        ("compare_errors (paired)", paired, None),
        ("check_consistency (NEES)", lambda: check_consistency(errors_xyz, cov), None),
        ("evaluate, intervals on", lambda: evaluate(truth, [estimate], with_ci), None),
        ("evaluate, no_ci", lambda: evaluate(truth, [estimate], no_ci), None),
    ]
    print(f"{N} matched poses, median / min of {opts.repeat} runs")
    medians = {}
    for name, fn, target in cases:
        med, best = timed(fn, opts.repeat)
        medians[name] = med
        verdict = "" if target is None else f"< {target} s {'ok' if med < target else 'MISSED'}"
        print(f"{name:<32} {med:>7.3f} s {best:>7.3f} s  {verdict}")
    cost = medians["evaluate, intervals on"] - medians["evaluate, no_ci"]
    verdict = "ok" if cost < TARGET_S else "MISSED"
    print(f"{'intervals in evaluate (diff)':<32} {cost:>7.3f} s {'':>9}  < {TARGET_S} s {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
