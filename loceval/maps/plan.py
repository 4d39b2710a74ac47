"""The building's plan as line segments, indexed to measure many map cells against it.

The plan's walls are sampled densely (every ``spacing_m``) into a KD-tree, each sample
tagged with its segment. A query point's few nearest samples name the segments measured
exactly (point to segment, not to the infinite line), so a distance is exact whenever the
nearest wall is among them and never more than ``spacing_m / 2`` too large otherwise.
Everything runs on arrays of points; nothing loops over cells or segments.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import KDTree

from loceval.core.arrays import FloatArray
from loceval.errors import InputError
from loceval.maps.buckets import SegmentBuckets
from loceval.maps.samples import sample_segments

__all__ = ["PlanIndex", "sample_segments"]

_MAX_SAMPLES: Final = 4_000_000
_NEIGHBOURS: Final = 4
_CHUNK: Final = 500_000
_BUCKET_M: Final = 1.0
"""The side of the lookup table's buckets (:mod:`loceval.maps.buckets`), metres."""
_REACH_M: Final = 1.0
"""Distances up to this are found through the lookup table; farther points use the tree."""


@dataclass(frozen=True, slots=True, eq=False)
class PlanIndex:
    """A floor plan's segments and a KD-tree of samples along them.

    Attributes:
        segments_xy: (K, 2, 2) segment end points, evaluation-frame metres.
        spacing_m: the sampling step.
        tree: KD-tree over the samples.
        owner: (S,) the segment of each sample.
        frames: (K, 5) each segment's start x, y, unit direction x, y and length.
        buckets: the lookup table of the segments near each square metre (None: a plan
            too large for one; the tree answers every point).
    """

    segments_xy: FloatArray
    spacing_m: float
    tree: KDTree
    owner: NDArray[np.intp]
    frames: FloatArray
    buckets: SegmentBuckets | None = None

    @classmethod
    def build(cls, segments_xy: FloatArray, *, spacing_m: float) -> PlanIndex:
        """Index a plan's segments.

        Args:
            segments_xy: (K, 2, 2) segments, metres.
            spacing_m: the sampling step (coarsened to at most 4,000,000 samples).

        Raises:
            InputError: the plan has no segment of finite, non-zero length.
        """
        segments = np.asarray(segments_xy, dtype=np.float64).reshape(-1, 2, 2)
        lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
        keep = np.isfinite(segments).all(axis=(1, 2)) & (lengths > 0)
        segments = segments[keep]
        if not len(segments):
            msg = "The building plan has no wall line to compare the map with; check the plan."
            raise InputError(msg, option="building")
        total = float(lengths[keep].sum())
        spacing = max(float(spacing_m), total / _MAX_SAMPLES)
        samples, owner = sample_segments(segments, spacing)
        ab = segments[:, 1] - segments[:, 0]
        length = np.linalg.norm(ab, axis=1)
        frames = np.column_stack([segments[:, 0], ab / length[:, None], length])
        buckets = SegmentBuckets.build(segments, size_m=_BUCKET_M, reach_m=_REACH_M)
        return cls(segments, spacing, KDTree(samples), owner, frames, buckets)

    @property
    def length_m(self) -> float:
        """Return the plan's total wall length, metres."""
        return float(np.linalg.norm(self.segments_xy[:, 1] - self.segments_xy[:, 0], axis=1).sum())

    def candidates(self, points_xy: FloatArray, *, k: int = _NEIGHBOURS) -> NDArray[np.intp]:
        """Return the segments of each point's ``k`` nearest samples (the ones to measure).

        Args:
            points_xy: (N, 2) points, metres.
            k: samples per point.

        Returns:
            (N, k) segment indices.
        """
        points = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        k = min(k, self.tree.n)
        _, idx = self.tree.query(points, k=k)
        out: NDArray[np.intp] = self.owner[np.asarray(idx).reshape(len(points), k)]
        return out

    def measure(
        self, points_xy: FloatArray, candidates: NDArray[np.intp]
    ) -> tuple[FloatArray, FloatArray]:
        """Return each point's exact distance to the nearest of its candidate segments.

        Args:
            points_xy: (N, 2) points, metres.
            candidates: (N, k) segment indices (:meth:`candidates`).

        Returns:
            (N,) distances, metres, and (N, 2) the nearest points on those segments.
        """
        points = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        distance = np.empty(len(points))
        closest = np.empty((len(points), 2))
        ax, ay, ux, uy, length = self.frames.T
        for start in range(0, len(points), _CHUNK):  # blocks bound the memory, not per point
            stop = start + _CHUNK
            near = candidates[start:stop]
            px, py = points[start:stop, 0:1], points[start:stop, 1:2]
            sx, sy, dx, dy = ax[near], ay[near], ux[near], uy[near]
            along = np.clip((px - sx) * dx + (py - sy) * dy, 0.0, length[near])
            fx, fy = sx + along * dx, sy + along * dy
            d2 = (px - fx) ** 2 + (py - fy) ** 2
            best = np.argmin(d2, axis=1)[:, None]
            distance[start:stop] = np.sqrt(np.take_along_axis(d2, best, axis=1)[:, 0])
            closest[start:stop, 0] = np.take_along_axis(fx, best, axis=1)[:, 0]
            closest[start:stop, 1] = np.take_along_axis(fy, best, axis=1)[:, 0]
        return distance, closest

    def nearest(self, points_xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return each point's distance to the plan and the nearest point on it.

        Points within the lookup table's reach of a wall are measured against their
        bucket's segments (exact); the others against their nearest samples' segments.

        Args:
            points_xy: (N, 2) points, metres.

        Returns:
            (N,) distances, metres, and (N, 2) the nearest plan points.
        """
        points = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        if self.buckets is None:
            return self.measure(points, self.candidates(points))
        listed, ok = self.buckets.lookup(points)
        distance, closest = self.measure(points, listed)
        rest = np.flatnonzero(~ok | (distance > self.buckets.reach_m))
        if len(rest):  # far from every wall, or off the table: the tree's candidates
            far, far_closest = self.measure(points[rest], self.candidates(points[rest]))
            better = ~ok[rest] | (far < distance[rest])
            distance[rest[better]] = far[better]
            closest[rest[better]] = far_closest[better]
        return distance, closest
