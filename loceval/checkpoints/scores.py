"""Scores of visits to control points, as the public SLAM benchmarks on building sites give.

- **Hilti SLAM Challenge 2023**: each control point's 3D error earns points in strict tiers,
  below 0.5 / 1 / 3 / 6 / 10 / 40 cm: 20 / 10 / 6 / 5 / 3 / 1 points, 0 beyond.
- **LaMAria**: the horizontal error earns points along the piecewise-linear curve through
  (0.05 m, 20), (0.2, 18), (0.5, 15), (1, 12), (2, 8), (5, 4), (10, 0): 20 below 5 cm, 0
  beyond 10 m.

Both are normalised as ``100 x sum / (20 x visits)``: 100 when every visit earns the most.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from loceval.core.arrays import FloatArray, IntArray

__all__ = [
    "HILTI_POINTS",
    "HILTI_TIERS_M",
    "LAMARIA_KNOTS",
    "hilti_score",
    "lamaria_score",
    "recall",
]

HILTI_TIERS_M = (0.005, 0.01, 0.03, 0.06, 0.10, 0.40)
HILTI_POINTS = (20, 10, 6, 5, 3, 1)
LAMARIA_KNOTS = (
    (0.05, 20.0),
    (0.2, 18.0),
    (0.5, 15.0),
    (1.0, 12.0),
    (2.0, 8.0),
    (5.0, 4.0),
    (10.0, 0.0),
)
_BEST = 20.0


def hilti_score(errors_3d_m: FloatArray) -> float:
    """Return the Hilti 2023 score (0..100) of visits' 3D errors, (V,) metres.

    A tier is strict: an error of exactly 1 cm earns the 3 cm tier's 6 points.
    """
    if errors_3d_m.size == 0:
        return float("nan")
    tier = np.searchsorted(np.asarray(HILTI_TIERS_M), errors_3d_m, side="right")
    points = np.append(np.asarray(HILTI_POINTS, dtype=np.float64), 0.0)[tier]
    return float(100.0 * points.sum() / (_BEST * errors_3d_m.size))


def lamaria_score(errors_h_m: FloatArray) -> float:
    """Return the LaMAria score (0..100) of visits' horizontal errors, (V,) metres."""
    if errors_h_m.size == 0:
        return float("nan")
    knots = np.asarray(LAMARIA_KNOTS)
    points = np.interp(errors_h_m, knots[:, 0], knots[:, 1])  # flat beyond both ends
    return float(100.0 * points.sum() / (_BEST * errors_h_m.size))


def recall(
    point_index: IntArray,
    errors_m: FloatArray,
    *,
    points: IntArray,
    thresholds_m: Sequence[float],
) -> dict[float, float]:
    """Return, per threshold, the share of ``points`` with at least one visit within it.

    Args:
        point_index: (V,) the control point of each visit.
        errors_m: (V,) each visit's error.
        points: the control points that count (unvisited ones count as misses).
        thresholds_m: distances, metres.
    """
    if points.size == 0:
        return {float(t): float("nan") for t in thresholds_m}
    best = np.full(int(max(points.max(), point_index.max(initial=0))) + 1, np.inf)
    np.minimum.at(best, point_index, errors_m)
    best = best[points]
    return {float(t): float((best <= t).mean()) for t in thresholds_m}
