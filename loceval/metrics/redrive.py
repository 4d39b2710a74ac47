"""Re-drive timing: whether a repeated run passed each point of the first run at the same time.

The reference robot re-drives a recorded path keeping the original timing within 1 s (its
Algorithm 1), because a system's results change with speed. :mod:`loceval.metrics.repeatability`
compares re-driven paths in space; this module adds time. For each position of the first
run, the later run's closest approach along its own path gives the time it passed there
(interpolated along the later path, resampled every centimetre); the timing difference is
that time minus the first run's, both counted from each run's start. Where the paths cross
or revisit a place, the closest approach is taken among the later path's points near the
same share of the way (the passes a few metres apart are told apart by their progress).
The stretches where the difference exceeds a tolerance (1 s) say where the runs were not
driven alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from scipy.spatial import KDTree

from loceval.core.arrays import FloatArray
from loceval.errors import InputError

__all__ = ["RedriveTiming", "TimingStretch", "redrive_timing"]

_SPACING_M: Final = 0.01
_MAX_SAMPLES: Final = 2_000_000
_NEIGHBOURS: Final = 16
_NEAR_M: Final = 0.25
"""Candidates within this of the closest one are judged by their progress along the path."""


@dataclass(frozen=True, slots=True)
class TimingStretch:
    """A stretch of the first run where the later run was off by more than the tolerance.

    Attributes:
        start_s: the first run's time where it starts, seconds from its start.
        duration_s: its length in the first run's time, seconds.
        max_abs_s: the largest timing difference in it, seconds (signed: + later run late).
    """

    start_s: float
    duration_s: float
    max_abs_s: float


@dataclass(frozen=True, slots=True, eq=False)
class RedriveTiming:
    """A later run's timing against the first run's, point by point.

    Attributes:
        t_s: (M,) the first run's times, seconds from its start.
        difference_s: (M,) the later run's time at its closest approach minus ``t_s``.
        distance_m: (M,) the closest approach's distance, metres.
        tolerance_s: the tolerance the stretches exceed.
        stretches: where ``|difference_s|`` exceeds the tolerance.
    """

    t_s: FloatArray
    difference_s: FloatArray
    distance_m: FloatArray
    tolerance_s: float
    stretches: tuple[TimingStretch, ...]

    @property
    def median_abs_s(self) -> float:
        """Median absolute timing difference, seconds."""
        return float(np.median(np.abs(self.difference_s)))

    @property
    def p95_abs_s(self) -> float:
        """95th percentile of the absolute timing difference, seconds."""
        return float(np.quantile(np.abs(self.difference_s), 0.95))

    @property
    def max_abs_s(self) -> float:
        """Largest absolute timing difference, seconds."""
        return float(np.abs(self.difference_s).max())

    @property
    def share_within(self) -> float:
        """Share of the first run's points passed within the tolerance."""
        return float(np.mean(np.abs(self.difference_s) <= self.tolerance_s))

    def to_dict(self) -> dict[str, object]:
        """Return the figures (no per-point arrays)."""
        return {
            "median_abs_s": self.median_abs_s,
            "p95_abs_s": self.p95_abs_s,
            "max_abs_s": self.max_abs_s,
            "tolerance_s": self.tolerance_s,
            "share_within": self.share_within,
            "stretches": [
                {"start_s": s.start_s, "duration_s": s.duration_s, "max_abs_s": s.max_abs_s}
                for s in self.stretches
            ],
        }


def redrive_timing(
    first_t_s: FloatArray,
    first_xyz: FloatArray,
    later_t_s: FloatArray,
    later_xyz: FloatArray,
    *,
    tolerance_s: float = 1.0,
) -> RedriveTiming:
    """Time a later run against the first, at each of the first run's positions.

    Args:
        first_t_s: (M,) the first run's times, seconds (any origin), increasing.
        first_xyz: (M, 3) its positions, metres.
        later_t_s: (N,) the later run's times, seconds, increasing.
        later_xyz: (N, 3) its positions, metres.
        tolerance_s: the timing difference a stretch must exceed, seconds (Algorithm 1: 1 s).

    Returns:
        The timing differences, their distribution and the stretches over the tolerance.

    Raises:
        InputError: a run has fewer than two positions or the lengths do not match.
    """
    t1, p1 = _run(first_t_s, first_xyz, "first")
    t2, p2 = _run(later_t_s, later_xyz, "later")
    walked2 = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p2, axis=0), axis=1))])
    total2 = max(float(walked2[-1]), 1e-12)
    spacing = max(_SPACING_M, total2 / _MAX_SAMPLES)
    along = np.linspace(0.0, walked2[-1], int(np.ceil(total2 / spacing)) + 1)
    samples = np.column_stack([np.interp(along, walked2, p2[:, k]) for k in range(3)])
    sample_t = np.interp(along, walked2, t2 - t2[0])
    share = along / total2
    walked1 = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p1, axis=0), axis=1))])
    progress1 = walked1 / max(float(walked1[-1]), 1e-12)
    k = min(_NEIGHBOURS, len(samples))
    dist, idx = KDTree(samples).query(p1, k=k)
    dist, idx = np.asarray(dist).reshape(len(p1), k), np.asarray(idx).reshape(len(p1), k)
    near = dist <= dist[:, :1] + _NEAR_M
    gap = np.where(near, np.abs(share[idx] - progress1[:, None]), np.inf)
    pick = np.argmin(gap, axis=1)[:, None]
    chosen = np.take_along_axis(idx, pick, axis=1)[:, 0]
    rel1 = t1 - t1[0]
    difference = sample_t[chosen] - rel1
    return RedriveTiming(
        t_s=rel1,
        difference_s=difference,
        distance_m=np.take_along_axis(dist, pick, axis=1)[:, 0],
        tolerance_s=float(tolerance_s),
        stretches=_stretches(rel1, difference, tolerance_s),
    )


def _run(t_s: FloatArray, xyz: FloatArray, which: str) -> tuple[FloatArray, FloatArray]:
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if len(t) != len(p) or len(t) < 2:
        msg = (
            f"The {which} run needs at least two positions with one time each, got "
            f"{len(p)} positions and {len(t)} times."
        )
        raise InputError(msg)
    keep = np.isfinite(t) & np.isfinite(p).all(axis=1)
    return t[keep], p[keep]


def _stretches(
    t: FloatArray, difference: FloatArray, tolerance_s: float
) -> tuple[TimingStretch, ...]:
    """The runs of consecutive points whose |difference| exceeds the tolerance."""
    over = np.abs(difference) > tolerance_s
    edges = np.flatnonzero(np.diff(np.concatenate([[0], over.astype(np.int8), [0]])))
    starts, stops = edges[::2], edges[1::2]  # [start, stop) index pairs
    out = []
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):  # one per stretch
        part = difference[a:b]
        worst = int(np.argmax(np.abs(part)))
        out.append(TimingStretch(float(t[a]), float(t[b - 1] - t[a]), float(part[worst])))
    return tuple(out)
