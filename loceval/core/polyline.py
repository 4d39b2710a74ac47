"""Distances from points to polylines, and polyline simplification.

One point-to-segment distance (:func:`segment_distances`, broadcasting) serves every use:
the exact distance to a whole polyline (:func:`polyline_distances`, brute force in chunks,
for checking a simplified or re-read path against the poses it stands for), the fast
distance to a long polyline through a KD-tree of its resampled points
(:class:`PolylineIndex`, for comparing re-driven paths) and Ramer-Douglas-Peucker
simplification (:func:`simplify_rdp`, for CAD files). Every function is vectorised: points
are handled in numpy blocks, never one by one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray
from loceval.errors import InputError

if TYPE_CHECKING:
    from scipy.spatial import KDTree

__all__ = [
    "RESAMPLE_SPACING_M",
    "PolylineIndex",
    "path_distances",
    "polyline_distances",
    "segment_distances",
    "simplify_rdp",
    "simplify_rdp_runs",
]

RESAMPLE_SPACING_M: Final = 0.001
"""Spacing of a :class:`PolylineIndex`'s resampled path: distances are within half of it."""
_MAX_SAMPLES: Final = 2_000_000
"""Most samples of a resampled path (its KD-tree); a path over 2 km is resampled coarser
(spacing = length / 2,000,000: still under 1 mm of error below 4 km)."""
_NEIGHBOURS: Final = 4
"""Nearest resampled vertices whose segments are measured exactly, per point."""
_CHUNK_POINTS: Final = 200_000
"""Points measured at once against a :class:`PolylineIndex` (bounds the exact step's memory)."""
_CHUNK_PAIRS: Final = 4_000_000
"""Point-segment pairs per block of :func:`polyline_distances` (about 100 MB)."""


def segment_distances(
    points_xyz: FloatArray, start_xyz: FloatArray, end_xyz: FloatArray
) -> FloatArray:
    """Distance from points to the segments ``start``-``end`` (not the infinite lines).

    The three arrays broadcast against each other on every axis but the last: (K, 3)
    points against (K, 3) segments gives one distance per row, (N, 1, 3) points against
    (1, M, 3) segments gives the (N, M) table. A zero-length segment is its start point.

    Args:
        points_xyz: (..., 3) points.
        start_xyz: (..., 3) segment starts.
        end_xyz: (..., 3) segment ends.

    Returns:
        The distances, in the points' units, with the broadcast shape without its last axis.
    """
    start = np.asarray(start_xyz, dtype=np.float64)
    ab = np.asarray(end_xyz, dtype=np.float64) - start
    ap = np.asarray(points_xyz, dtype=np.float64) - start
    length2 = np.einsum("...j,...j->...", ab, ab)
    along = np.einsum("...j,...j->...", ap, ab)
    t = np.divide(along, length2, out=np.zeros_like(along), where=length2 > 0.0)
    diff = ap - np.clip(t, 0.0, 1.0)[..., None] * ab
    out: FloatArray = np.sqrt(np.einsum("...j,...j->...", diff, diff))
    return out


def _segments(vertices_xyz: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The (M-1, 3) starts and ends of a polyline's segments; one vertex is one point.

    Raises:
        InputError: the polyline has no vertex.
    """
    vertices = np.asarray(vertices_xyz, dtype=np.float64).reshape(-1, 3)
    if len(vertices) == 0:
        msg = "The polyline has no vertex; give it at least one point."
        raise InputError(msg)
    if len(vertices) == 1:
        return vertices, vertices  # one zero-length segment
    return vertices[:-1], vertices[1:]


def polyline_distances(points_xyz: FloatArray, vertices_xyz: FloatArray) -> FloatArray:
    """Exact distance from each point to the nearest segment of a polyline.

    Brute force over every point-segment pair, in blocks of about 4,000,000 pairs: exact,
    and fast enough for checking a simplified or re-read path against its poses. For long
    paths measured often, :class:`PolylineIndex` is faster.

    Args:
        points_xyz: (N, 3) points.
        vertices_xyz: (M, 3) polyline vertices, M >= 1.

    Returns:
        (N,) distances in the points' units.

    Raises:
        InputError: the polyline has no vertex.
    """
    points = np.asarray(points_xyz, dtype=np.float64).reshape(-1, 3)
    a, b = _segments(vertices_xyz)
    out = np.empty(len(points))
    step = max(1, _CHUNK_PAIRS // len(a))
    for k in range(0, len(points), step):  # one block per ~4M pairs, not per point
        p = points[k : k + step]
        out[k : k + step] = segment_distances(p[:, None, :], a[None], b[None]).min(axis=1)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class PolylineIndex:
    """A polyline resampled densely into a KD-tree, to measure many points against it.

    Samples are placed every ``spacing_m`` along the path (and at its end), each tagged
    with the segment it lies on. Any point of the polyline then lies within
    ``spacing_m / 2`` of a sample, so the nearest sample to a query point is at most
    ``spacing_m / 2`` farther than the polyline itself. The exact point-to-segment distance
    to the segments of the few nearest samples is therefore never below the true distance
    and at most ``spacing_m / 2`` above it.

    Attributes:
        vertices: (M, 3) the polyline (a single vertex is doubled into one segment).
        samples: (S, 3) the resampled points.
        segment: (S,) the segment each sample lies on.
        spacing_m: the spacing along the path, metres (the error bound is half of it).
        tree: the KD-tree over ``samples``.
    """

    vertices: FloatArray
    samples: FloatArray
    segment: IntArray
    spacing_m: float
    tree: KDTree

    @classmethod
    def build(
        cls, vertices_xyz: FloatArray, *, spacing_m: float = RESAMPLE_SPACING_M
    ) -> PolylineIndex:
        """Resample a polyline at ``spacing_m`` (coarser past 2,000,000 samples) and index it.

        Args:
            vertices_xyz: (M, 3) polyline vertices, metres, M >= 1.
            spacing_m: the spacing of the samples along the path, metres.

        Returns:
            The index.

        Raises:
            InputError: the polyline has no vertex.
        """
        a, b = _segments(vertices_xyz)
        vertices = np.vstack([a, b[-1:]])
        ab = b - a
        length = np.linalg.norm(ab, axis=1)
        along = np.concatenate([[0.0], np.cumsum(length)])
        total = float(along[-1])
        spacing_m = max(spacing_m, total / _MAX_SAMPLES, 1e-9)
        # Uniform in arc length (across vertices), so a densely recorded path is not
        # sampled more finely than needed; the last vertex closes it.
        at = np.append(np.arange(0.0, total, spacing_m), total)
        segment = np.clip(np.searchsorted(along, at, side="right") - 1, 0, len(ab) - 1)
        fraction = np.divide(
            at - along[segment],
            length[segment],
            out=np.zeros_like(at),
            where=length[segment] > 0.0,
        )
        samples = vertices[segment] + np.clip(fraction, 0.0, 1.0)[:, None] * ab[segment]
        # Imported here: scipy.spatial costs a tenth of a second to import, which the CAD
        # files (simplify_rdp) and the reports do not need.
        from scipy.spatial import KDTree  # noqa: PLC0415

        tree = KDTree(samples, compact_nodes=False)  # faster queries far from the path
        return cls(vertices, samples, segment.astype(np.intp), spacing_m, tree)

    def distances(self, points_xyz: FloatArray) -> FloatArray:
        """Distance from each point to the polyline, metres.

        Never below the exact distance and at most ``spacing_m / 2`` above it (0.5 mm at
        the default spacing). Vectorised: the points are handled in chunks, not one by one.

        Args:
            points_xyz: (N, 3) points.

        Returns:
            (N,) distances.
        """
        points = np.asarray(points_xyz, dtype=np.float64).reshape(-1, 3)
        a, b = self.vertices[:-1], self.vertices[1:]
        k = min(_NEIGHBOURS, len(self.samples))
        out = np.empty(len(points))
        for start in range(0, len(points), _CHUNK_POINTS):  # chunks of points, not each point
            p = points[start : start + _CHUNK_POINTS]
            _, idx = self.tree.query(p, k=k)
            seg = self.segment[np.asarray(idx, dtype=np.intp).reshape(len(p), k)]
            out[start : start + len(p)] = segment_distances(p[:, None, :], a[seg], b[seg]).min(1)
        return out


def path_distances(points_xyz: FloatArray, vertices_xyz: FloatArray) -> FloatArray:
    """Distance from each point to a polyline (point-to-segment), fast for long paths.

    See :class:`PolylineIndex`: at most 0.5 mm above the exact distance for paths up to
    2 km, never below it.

    Args:
        points_xyz: (N, 3) points, metres.
        vertices_xyz: (M, 3) polyline vertices, M >= 1.

    Returns:
        (N,) distances, metres.

    Raises:
        InputError: the polyline has no vertex.
    """
    return PolylineIndex.build(vertices_xyz).distances(points_xyz)


def simplify_rdp(points_xyz: FloatArray, tolerance: float) -> tuple[IntArray, float]:
    """Ramer-Douglas-Peucker simplification of a 3D polyline.

    Iterative and vectorized: every pending segment of one refinement level is measured in
    a single numpy pass (a work list instead of recursion, so no recursion limit and no
    Python loop over points). Distances are to the segment, not the infinite line, so
    closed loops (first point == last point) simplify correctly.

    The returned deviation is the largest distance from a dropped vertex to the simplified
    segment that replaces it. Because the distance to a segment is convex, this is also the
    largest distance from any point of the original polyline to the simplified one.

    Args:
        points_xyz: (N, 3) vertices.
        tolerance: largest allowed deviation, in the points' units; 0 keeps every vertex.

    Returns:
        The (M,) increasing indices of the kept vertices (first and last always kept), and
        the largest deviation introduced (0.0 when nothing was dropped).
    """
    points = np.asarray(points_xyz, dtype=np.float64)
    n = points.shape[0]
    if n <= 2 or tolerance <= 0.0:
        return np.arange(n, dtype=np.intp), 0.0
    keep, deviation = simplify_rdp_runs(
        points, np.array([0], dtype=np.intp), np.array([n], dtype=np.intp), tolerance
    )
    return np.flatnonzero(keep), deviation


def simplify_rdp_runs(
    points_xyz: FloatArray, starts: IntArray, stops: IntArray, tolerance: float
) -> tuple[BoolArray, float]:
    """Simplify many polylines, each a run of consecutive points, in one work list.

    The same simplification as :func:`simplify_rdp` applied to every ``points[start:stop]``
    on its own, with the runs of all polylines refined together level by level (a CAD
    file's paths are thousands of short runs, one per colour band: one numpy pass per
    level instead of one Python call per run). Runs may share an end point (one run ends
    where the next begins); run ends are always kept.

    Args:
        points_xyz: (N, 3) vertices.
        starts: (R,) first index of each run.
        stops: (R,) one past the last index of each run (``stop - start >= 1``).
        tolerance: largest allowed deviation, in the points' units; 0 keeps every vertex.

    Returns:
        The (N,) mask of kept vertices (every run's ``points[start:stop][mask[start:stop]]``
        is its simplified polyline), and the largest deviation introduced over all runs.
    """
    points = np.asarray(points_xyz, dtype=np.float64)
    n = points.shape[0]
    starts = np.asarray(starts, dtype=np.intp)
    ends = np.asarray(stops, dtype=np.intp) - 1
    keep = np.zeros(n, dtype=bool)
    keep[starts] = True
    keep[ends] = True
    if tolerance <= 0.0:
        keep[:] = True
        return keep, 0.0
    deviation = 0.0
    while starts.size:
        counts = ends - starts - 1
        nonempty = counts > 0
        starts, ends, counts = starts[nonempty], ends[nonempty], counts[nonempty]
        if not starts.size:
            break
        first = np.cumsum(counts) - counts  # where each segment's interior starts
        segment = np.repeat(np.arange(starts.size), counts)
        inner = starts[segment] + 1 + (np.arange(int(counts.sum())) - first[segment])
        dist = segment_distances(points[inner], points[starts][segment], points[ends][segment])
        peak = np.maximum.reduceat(dist, first)
        at_peak = np.flatnonzero(dist == peak[segment])
        # on ties (zigzags, quantized data) split nearest the middle: the work list then
        # halves each level instead of peeling off one vertex per level
        off_centre = np.abs(2 * inner[at_peak] - (starts + ends)[segment[at_peak]])
        at_peak = at_peak[np.lexsort((off_centre, segment[at_peak]))]
        argmax = at_peak[np.unique(segment[at_peak], return_index=True)[1]]
        split = peak > tolerance
        if (~split).any():
            deviation = max(deviation, float(peak[~split].max()))
        cut = inner[argmax[split]]
        keep[cut] = True
        starts = np.concatenate([starts[split], cut])
        ends = np.concatenate([cut, ends[split]])
    return keep, deviation
