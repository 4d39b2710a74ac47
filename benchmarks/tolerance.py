"""Time the tolerance work on a long run: stretches, their rooms, the greatest errors.

Run by hand: ``.venv/bin/python -m benchmarks.tolerance [--repeat N]``.
Targets on a 2-core machine, for 1,000,000 matched poses (100 Hz, 2.8 h) whose error
crosses the tolerance about 20,000 times: the stretches beyond it (``failing_spans``) under
1 s; placing them in 200 rooms (``locate_verdict``, every pose of every stretch tested)
under 2 s; the 1,000 greatest errors (``--worst 1000``, the option's bound) under 1 s.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from loceval.assessment.spaces import Building, Space, locate_verdict
from loceval.assessment.verdict import Tolerance, tolerance_verdict_of
from loceval.metrics.pose_errors import ErrorSeries, greatest_errors
from loceval.trajectory import Trajectory

N = 1_000_000
TARGETS_S = {"failing_spans": 1.0, "locate_verdict 200 rooms": 2.0, "greatest_errors 1000": 1.0}


def _run(rng: np.random.Generator) -> tuple[Trajectory, ErrorSeries]:
    stamps = 1_700_000_000_000_000_000 + np.arange(N, dtype=np.int64) * 10_000_000
    t = np.arange(N) / 100.0
    # a walk through a 20 x 10 grid of 5 m rooms (100 m x 50 m), 1.2 m above the floor
    xy = np.stack([50 + 48 * np.sin(t / 97.0), 25 + 24 * np.sin(t / 61.0)], axis=1)
    truth = Trajectory(stamps, np.column_stack([xy, np.full(N, 1.2)]), name="truth")
    error = 0.02 + 0.01 * np.sin(t / 1.7) + rng.normal(0, 0.002, N)
    return truth, ErrorSeries(np.abs(error), stamps, "m")


def _rooms() -> Building:
    spaces = [
        Space(
            f"{i}.{j:02d}",
            [(5 * i, 5 * j), (5 * i + 5, 5 * j), (5 * i + 5, 5 * j + 5), (5 * i, 5 * j + 5)],
        )
        for i in range(20)
        for j in range(10)
    ]
    return Building("grid.ifc", tuple(spaces))


def main() -> None:
    """Print the median and best wall time of each case against its target."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    truth, errors = _run(np.random.default_rng(7))
    tolerance = Tolerance(0.025, 0.95)
    t0 = int(truth.stamps_ns[0])
    verdict = tolerance_verdict_of(errors, truth, tolerance, t0, None)
    building = _rooms()
    cases: dict[str, Callable[[], object]] = {
        "failing_spans": lambda: tolerance_verdict_of(errors, truth, tolerance, t0, None),
        "locate_verdict 200 rooms": lambda: locate_verdict(verdict, truth.positions_xyz, building),
        "greatest_errors 1000": lambda: greatest_errors(errors, truth, count=1000),
    }
    print(f"{len(verdict.failing_spans):,} stretches beyond {tolerance}")
    for name, run in cases.items():
        times = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            run()
            times.append(time.perf_counter() - start)
        print(
            f"{name}: median {statistics.median(times):.3f} s, best {min(times):.3f} s "
            f"(target {TARGETS_S[name]:g} s)"
        )


if __name__ == "__main__":
    main()
