"""Time the polyline work that must stay fast on long paths (moved here from timed tests).

Run by hand: ``.venv/bin/python -m benchmarks.polyline [--repeat N]``.
Targets on a 2-core machine: Douglas-Peucker simplification of a 100,000-pose noisy walk and
of a 100,000-vertex zigzag (every vertex kept, ties everywhere) together under 10 s; 50,000
re-driven points against a 50,000-vertex path (``path_distances``) under 3 s.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from loceval.core.polyline import path_distances, simplify_rdp

N = 100_000
TARGETS_S = {"simplify_rdp 3 x 100,000": 10.0, "path_distances 50,000 x 50,000": 3.0}


def _simplify_cases(rng: np.random.Generator) -> Callable[[], object]:
    t = np.linspace(0, 60 * np.pi, N)
    walk = np.stack([5 * np.cos(t) + 0.01 * t, 3 * np.sin(t), 1.3 + 0.1 * np.sin(5 * t)], 1)
    noisy = walk + rng.normal(0, 0.0005, walk.shape)
    zigzag = np.stack([np.arange(N) * 0.01, (np.arange(N) % 2) * 0.1, np.zeros(N)], 1)
    return lambda: [simplify_rdp(path, 0.001) for path in (walk, noisy, zigzag)]


def _loop(n: int, offset_m: float = 0.0) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    radius = 5.0 + offset_m
    return np.stack([radius * np.cos(t), radius * np.sin(t), np.zeros(n)], axis=1)


def _distance_case(rng: np.random.Generator) -> Callable[[], object]:
    base = _loop(50_000)
    redriven = _loop(50_000, offset_m=0.03)[rng.permutation(50_000)]
    return lambda: path_distances(redriven, base)


def main() -> None:
    """Print the median and best wall time of each case against its target."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rng = np.random.default_rng(7)
    cases = dict(zip(TARGETS_S, (_simplify_cases(rng), _distance_case(rng)), strict=True))
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
