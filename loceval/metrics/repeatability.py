"""Repeatability of a path: how closely later recordings re-drive a first one, in space.

The reference-robot paper's re-drive test: a path recorded once is driven again, and every
position of the re-driven path is measured against the first path (a polyline through its
positions, point-to-segment), not against the pose at the same time. The median and the
largest distance summarise how closely it was re-driven (the paper reports 10.1 cm and
24.6 cm for its robot).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.core.polyline import PolylineIndex
from loceval.errors import InputError

__all__ = ["PathDeviation", "finite_positions", "path_deviations"]


@dataclass(frozen=True, slots=True)
class PathDeviation:
    """One path's distances to the baseline path.

    Attributes:
        points: positions measured.
        median_m: median distance from those positions to the baseline path, metres.
        max_m: largest such distance, metres.
    """

    points: int
    median_m: float
    max_m: float


def finite_positions(positions_xyz: FloatArray) -> FloatArray:
    """The rows of an (N, 3) position array whose three coordinates are all finite."""
    xyz = np.asarray(positions_xyz, dtype=np.float64).reshape(-1, 3)
    out: FloatArray = xyz[np.isfinite(xyz).all(axis=1)]
    return out


def path_deviations(
    baseline_xyz: FloatArray, paths_xyz: Sequence[FloatArray]
) -> tuple[PathDeviation, ...]:
    """Measure every path's positions against the baseline path, in space.

    The baseline is indexed once (:class:`loceval.core.polyline.PolylineIndex`): each distance
    is at most 0.5 mm above the exact point-to-segment distance for paths up to 2 km,
    never below it.

    Args:
        baseline_xyz: (M, 3) the baseline path's positions, metres, M >= 1, finite.
        paths_xyz: the later paths, each (N, 3) positions, metres, N >= 1, finite.

    Returns:
        One deviation per path, in the order given.

    Raises:
        InputError: the baseline or a path has no position.
    """
    if not paths_xyz:
        return ()
    index = PolylineIndex.build(baseline_xyz)
    out = []
    for k, xyz in enumerate(paths_xyz):  # one vectorised pass per recording, not per position
        distances = index.distances(xyz)
        if len(distances) == 0:
            msg = f"Path {k} has no position to compare; leave it out or give it positions."
            raise InputError(msg)
        out.append(
            PathDeviation(len(distances), float(np.median(distances)), float(distances.max()))
        )
    return tuple(out)
