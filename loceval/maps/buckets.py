"""A bucket grid over the plan: each square bucket lists the wall segments near it.

Measuring hundreds of thousands of map cells against the plan is dominated by finding each
cell's candidate segments. The KD-tree of wall samples (:class:`~loceval.maps.plan.PlanIndex`)
answers any point but walks a tree per point; most map cells lie within a metre of a wall,
where a lookup table answers in one indexing operation: the plane is cut into square
buckets of ``size_m`` and each bucket lists every segment that comes within
``size_m * √2 / 2 + reach_m`` of its centre (found from samples of the segments, every
``size_m``, so the lists are a superset). A point whose nearest listed segment is at
most ``reach_m`` away has its exact nearest segment among them (every segment within
``reach_m`` of a point is listed in the point's bucket); any other point (far from every
wall, outside the grid, or in a bucket with more than :data:`MAX_PER_BUCKET` segments) is
left to the KD-tree.

The table is built with array operations (no loop over segments or buckets) and only when
it stays small (:data:`MAX_TABLE_ENTRIES`); a plan spread over kilometres keeps the KD-tree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from loceval.core.arrays import BoolArray, FloatArray
from loceval.maps.samples import sample_segments

__all__ = ["MAX_PER_BUCKET", "MAX_TABLE_ENTRIES", "SegmentBuckets"]

MAX_PER_BUCKET: Final = 16
"""Most segments a bucket lists; a busier bucket's points go to the KD-tree."""
MAX_TABLE_ENTRIES: Final = 8_000_000
"""Most table entries (buckets x listed segments): 32 MB of int32."""
_MAX_PAIRS: Final = 20_000_000
"""Most (bucket, segment) pairs built before they are made unique."""


@dataclass(frozen=True, slots=True, eq=False)
class SegmentBuckets:
    """The lookup table: bucket -> the segments near it.

    Attributes:
        low: (2,) the corner of bucket (0, 0), metres.
        size_m: a bucket's side, metres.
        reach_m: distances up to this are exact when found through the table.
        shape: buckets along x and y.
        table: (buckets, K) int32 segment indices, -1 where a bucket lists fewer (a row
            of -1: no segment near, or too many).
    """

    low: FloatArray
    size_m: float
    reach_m: float
    shape: tuple[int, int]
    table: NDArray[np.int32]

    @classmethod
    def build(
        cls, segments_xy: FloatArray, *, size_m: float, reach_m: float
    ) -> SegmentBuckets | None:
        """Build the table of a plan's segments, or None when it would be too large.

        Args:
            segments_xy: (K, 2, 2) segments of non-zero length, metres.
            size_m: a bucket's side, metres.
            reach_m: the distance up to which lookups are exact, metres.
        """
        spacing = size_m
        samples, owner = sample_segments(segments_xy, spacing)
        radius = size_m * math.sqrt(0.5) + reach_m + spacing / 2.0
        steps = math.ceil(radius / size_m + 0.5)  # buckets whose centre can be that near
        low = samples.min(axis=0) - (steps + 1) * size_m
        high = samples.max(axis=0) + (steps + 1) * size_m
        nx, ny = (int(v) for v in np.ceil((high - low) / size_m))
        offsets = np.arange(-steps, steps + 1)
        if nx * ny * 2 > MAX_TABLE_ENTRIES or len(samples) * len(offsets) ** 2 > _MAX_PAIRS:
            return None
        ij = np.floor((samples - low) / size_m).astype(np.int64)
        dx, dy = np.meshgrid(offsets, offsets, indexing="ij")
        bx = (ij[:, 0:1] + dx.reshape(1, -1)).reshape(-1)
        by = (ij[:, 1:2] + dy.reshape(1, -1)).reshape(-1)
        seg = np.repeat(owner.astype(np.int64), len(offsets) ** 2)
        # keep only buckets whose centre lies within the radius of the sample (a disc)
        centre = (np.column_stack([bx, by]) + 0.5) * size_m + low
        near = np.linalg.norm(centre - np.repeat(samples, len(offsets) ** 2, axis=0), axis=1)
        keep = near <= radius
        n_segments = len(segments_xy)
        key = np.unique((bx[keep] * ny + by[keep]) * n_segments + seg[keep])
        bucket, segment = key // n_segments, key % n_segments
        counts = np.bincount(bucket, minlength=nx * ny)
        width = int(min(counts.max(initial=0), MAX_PER_BUCKET))
        if width == 0 or nx * ny * width > MAX_TABLE_ENTRIES:
            return None
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        rank = np.arange(len(key)) - first[bucket]  # position within its bucket (sorted)
        table = np.full((nx * ny, width), -1, dtype=np.int32)
        fits = rank < width
        table[bucket[fits], rank[fits]] = segment[fits]
        table[counts > MAX_PER_BUCKET] = -1  # too busy: those points go to the KD-tree
        return cls(low, float(size_m), float(reach_m), (nx, ny), table)

    def lookup(self, points_xy: FloatArray) -> tuple[NDArray[np.intp], BoolArray]:
        """Return each point's listed segments (padded with its first) and whether it has any.

        Args:
            points_xy: (N, 2) points, metres.

        Returns:
            (N, K) segment indices (rows of points without a list hold 0) and (N,) whether
            the point's bucket lists segments.
        """
        ij = np.floor((points_xy - self.low) / self.size_m)
        nx, ny = self.shape
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        flat = np.where(inside, ij[:, 0] * ny + ij[:, 1], 0).astype(np.intp)
        listed = self.table[flat]
        ok = inside & (listed[:, 0] >= 0)
        padded = np.where(listed >= 0, listed, listed[:, :1])  # a duplicate changes no minimum
        out: NDArray[np.intp] = np.where(ok[:, None], padded, 0).astype(np.intp)
        return out, ok
