"""The robot's map against the building's plan (the reference-robot paper's Figs. 4 and 5).

A SLAM map lives in the estimate's frame; the evaluation's alignment of that estimate
(or a given transform) places it on the plan. :func:`evaluate_map` then measures

- the wall cells (occupied cells with a free 4-neighbour: the walls the robot saw) against
  the plan's walls: RMSE, mean, median, 95th percentile, max, and the share within each
  threshold;
- the share of the plan's wall length the map saw, counted only where the robot mapped;
- the best robust rigid and similarity fits of the cells onto the plan
  (:mod:`loceval.maps.fit`) and the same figures after each: a map that is right but placed
  wrong is good after the rigid fit, a map that drifts in scale is good only after the
  similarity fit, and a bent map is good after neither;
- clutter: wall cells farther than ``clutter_m`` from every plan wall after the
  similarity fit (furniture, shelves: "not in the plan"), counted and kept out of every
  wall figure;
- the wall distances by region (square tiles of the plan frame), to show where it is off.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter

from loceval.core.arrays import BoolArray, FloatArray
from loceval.core.geometry import SimilarityTransform
from loceval.core.quantiles import quantiles
from loceval.errors import InputError, MetricError
from loceval.maps.axis_scale import AxisScales, fit_axis_scales
from loceval.maps.fit import Fit2D, fit_to_plan
from loceval.maps.grid import FREE, OCCUPIED, OccupancyGrid
from loceval.maps.plan import PlanIndex, sample_segments

if TYPE_CHECKING:
    from loceval.maps.snapshot import MapSnapshot

__all__ = ["MapEvaluation", "WallFigures", "evaluate_map"]

_FIT_CELLS: Final = 8_000
"""Most wall cells the fits iterate on (evenly spread); the figures use every cell."""
_START_M: Final = 2.0
"""The fits' first inlier distance at least: a placement off by a metre is still found."""
_COVERED_M: Final = 0.5
"""A plan wall counts for the coverage where the map has free space within this."""
_REGION_M: Final = 5.0
"""The side of the square tiles of the errors by region, metres."""


@dataclass(frozen=True, slots=True)
class WallFigures:
    """The wall cells' distances to the plan, after one placement or fit.

    Attributes:
        rmse: root mean square distance, metres.
        mean: mean, metres.
        median: median, metres.
        p95: 95th percentile, metres.
        max: largest, metres.
        n: wall cells measured (clutter left out).
        within: share of cells within each threshold (metres).
        plan_coverage: share of the plan's wall length (where the robot mapped) that has a
            wall cell within the coverage tolerance, 0-1; None when the map covers no wall.
    """

    rmse: float
    mean: float
    median: float
    p95: float
    max: float
    n: int
    within: Mapping[float, float]
    plan_coverage: float | None

    def distance_dict(self) -> dict[str, float | int]:
        """Return ``wall_distance_m``: rmse, mean, median, p95, max, n."""
        return {
            "rmse": self.rmse,
            "mean": self.mean,
            "median": self.median,
            "p95": self.p95,
            "max": self.max,
            "n": self.n,
        }

    def to_dict(self) -> dict[str, object]:
        """Return the figures: wall_distance_m, within, plan_coverage."""
        return {
            "wall_distance_m": self.distance_dict(),
            "within": {f"{t:g}": share for t, share in self.within.items()},
            "plan_coverage": self.plan_coverage,
        }


@dataclass(frozen=True, slots=True, eq=False)
class MapEvaluation:
    """A map measured against the plan.

    Attributes:
        source: the map's source (file or ``bag@topic``).
        resolution_m: the map's cell size, metres.
        shape: the grid's (rows, columns).
        estimate: the estimate whose alignment placed the map (None: a given transform).
        placement: map frame -> plan (evaluation) frame.
        clutter_m: the clutter distance, metres.
        coverage_tolerance_m: how near a wall cell must be for a plan wall to count as seen.
        placed: the figures as placed.
        rigid: the rigid fit (carrying the placed map onto the plan) and its figures.
        similarity: the similarity fit and its figures.
        clutter_cells: wall cells farther than ``clutter_m`` from the plan after the
            similarity fit.
        cells_xy: (N, 2) every wall cell's centre, placed, metres.
        distance_m: (N,) each wall cell's distance to the plan as placed.
        fitted_distance_m: (N,) the same after the similarity fit.
        clutter: (N,) bool, the cell is clutter.
        regions: the errors by region: tile centre, cells and RMSE as placed.
        plan_xy: (K, 2, 2) the plan's segments, evaluation frame (for the figures).
        warnings: what the user should know.
        history: a bag topic's messages judged one by one, the last included
            (:mod:`loceval.maps.history`); empty for a map file.
        history_note: how the messages were chosen when the topic held more than were
            judged.
        axis_scales: the per-axis scales along the map's grid axes
            (:mod:`loceval.maps.axis_scale`), None when unobservable.
    """

    source: str
    resolution_m: float
    shape: tuple[int, int]
    estimate: str | None
    placement: SimilarityTransform
    clutter_m: float
    coverage_tolerance_m: float
    placed: WallFigures
    rigid: tuple[Fit2D, WallFigures]
    similarity: tuple[Fit2D, WallFigures]
    clutter_cells: int
    cells_xy: FloatArray
    distance_m: FloatArray
    fitted_distance_m: FloatArray
    clutter: BoolArray
    regions: tuple[dict[str, float | int], ...] = ()
    plan_xy: FloatArray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    warnings: tuple[str, ...] = ()
    history: tuple[MapSnapshot, ...] = ()
    history_note: str | None = None
    axis_scales: AxisScales | None = None

    @property
    def scale_error_pct(self) -> float:
        """How much longer (+) or shorter (-) the map is than the plan, percent."""
        return (1.0 / self.similarity[0].scale - 1.0) * 100.0

    def drift_sentence(self) -> str:
        """Return the similarity scale in words ("the map is 1.2 % short")."""
        pct = self.scale_error_pct
        return f"the map is {abs(pct):.2g} % {'short' if pct < 0 else 'long'}"

    def to_dict(self) -> dict[str, object]:
        """Return the result document's ``map`` object."""
        fit = {}
        for name, (found, figures) in (("rigid", self.rigid), ("similarity", self.similarity)):
            fit[name] = {**found.to_dict(), **figures.to_dict(), "cells_fitted": found.kept}
        return {
            "source": self.source,
            "resolution_m": self.resolution_m,
            "size_cells": [self.shape[1], self.shape[0]],
            "placed_by": {"estimate": self.estimate, "transform": self.placement.to_dict()},
            "wall_cells": len(self.cells_xy),
            **self.placed.to_dict(),
            "clutter_cells": self.clutter_cells,
            "clutter_m": self.clutter_m,
            "coverage_tolerance_m": self.coverage_tolerance_m,
            "scale_error_pct": self.scale_error_pct,
            "drift": self.drift_sentence(),
            "fit": fit,
            "axis_scales": None if self.axis_scales is None else self.axis_scales.to_dict(),
            "regions": [dict(r) for r in self.regions],
            "warnings": list(self.warnings),
            "history": [snapshot.to_dict() for snapshot in self.history],
            "history_note": self.history_note,
        }


def evaluate_map(
    grid: OccupancyGrid,
    plan_segments: FloatArray,
    placement: SimilarityTransform,
    *,
    thresholds_m: Sequence[float] = (0.05, 0.10, 0.15),
    clutter_m: float = 0.5,
    estimate: str | None = None,
) -> MapEvaluation:
    """Measure a map against the plan.

    Args:
        grid: the map, in its own (the estimate's) frame.
        plan_segments: (K, 2, 2) the plan's walls in the evaluation frame, metres.
        placement: map frame -> evaluation frame (the estimate's alignment).
        thresholds_m: the distances of the share-within figures.
        clutter_m: occupied cells farther than this from every wall after the similarity
            fit are clutter.
        estimate: the name of the estimate whose alignment placed the map.

    Returns:
        The figures, fits and per-cell distances.

    Raises:
        InputError: the map has no occupied cell, or none that borders free space.
        MetricError: the map and the plan do not overlap.
    """
    occupied = grid.states == OCCUPIED
    if not occupied.any():
        msg = (
            f"The map {grid.source!r} has no occupied cell, so it shows no wall to compare "
            "with the plan; check its thresholds (occupied_thresh, negate) or the topic."
        )
        raise InputError(msg, option="map")
    walls = grid.wall_mask()
    rows, cols = np.nonzero(walls)
    if not len(rows):
        msg = (
            f"The map {grid.source!r} has occupied cells but none next to free space (no "
            "wall the robot saw); check its free_thresh and negate."
        )
        raise InputError(msg, option="map")
    local = grid.cell_centres(rows, cols)
    cells = placement.apply_positions(np.column_stack([local, np.zeros(len(local))]))[:, :2]
    resolution = grid.resolution_m * placement.scale
    plan = PlanIndex.build(plan_segments, spacing_m=resolution)
    _check_overlap(cells, plan.segments_xy, grid.source)
    step = max(1, len(cells) // _FIT_CELLS)
    start = max(_START_M, 4.0 * clutter_m)
    similarity = fit_to_plan(
        cells[::step], plan, with_scale=True, start_m=start, floor_m=resolution
    )
    rigid = fit_to_plan(cells[::step], plan, with_scale=False, start_m=start, floor_m=resolution)
    distance, _ = plan.nearest(cells)
    fitted_cells = similarity.apply(cells)
    fitted, _ = plan.nearest(fitted_cells)
    clutter = fitted > clutter_m
    if clutter.all():
        msg = (
            f"Every wall cell of the map {grid.source!r} is farther than {clutter_m:g} m from "
            "the plan even after the best fit; the map and the plan do not overlap."
        )
        raise MetricError(msg, option="map")
    rigid_d, _ = plan.nearest(rigid.apply(cells))
    axes = _grid_axes_rad(grid, placement) + similarity.rotation_rad
    per_axis = fit_axis_scales(
        fitted_cells[::step], plan, axes_rad=axes, start_m=clutter_m, floor_m=resolution
    )
    tolerance = max(max(thresholds_m, default=0.15), 2.0 * resolution)
    coverage = _Coverage.of(grid, walls, rows[~clutter], cols[~clutter], tolerance)
    plan_samples, _ = sample_segments(plan.segments_xy, 2.0 * resolution)
    to_map = placement.inverse()

    def figures(d: FloatArray, fit: Fit2D | None) -> WallFigures:
        plan_in_map = plan_samples if fit is None else fit.inverse_apply(plan_samples)
        xyz = np.column_stack([plan_in_map, np.zeros(len(plan_in_map))])
        share = coverage.share(to_map.apply_positions(xyz)[:, :2])
        return _figures(d[~clutter], thresholds_m, share)

    return MapEvaluation(
        source=grid.source,
        resolution_m=grid.resolution_m,
        shape=grid.shape,
        estimate=estimate,
        placement=placement,
        clutter_m=clutter_m,
        coverage_tolerance_m=tolerance,
        placed=figures(distance, None),
        rigid=(rigid, figures(rigid_d, rigid)),
        similarity=(similarity, figures(fitted, similarity)),
        clutter_cells=int(clutter.sum()),
        cells_xy=cells,
        distance_m=distance,
        fitted_distance_m=fitted,
        clutter=clutter,
        regions=_regions(cells[~clutter], distance[~clutter]),
        plan_xy=plan.segments_xy,
        warnings=_warnings(similarity, int(clutter.sum()), len(cells)),
        axis_scales=None if per_axis is None else per_axis.times(similarity.scale),
    )


def _grid_axes_rad(grid: OccupancyGrid, placement: SimilarityTransform) -> float:
    """The direction of the grid's x axis (its columns) in the evaluation frame."""
    yaw = grid.origin_yaw_rad
    axis = placement.rotation @ np.array([math.cos(yaw), math.sin(yaw), 0.0])
    return math.atan2(float(axis[1]), float(axis[0]))


def _check_overlap(cells: FloatArray, segments: FloatArray, source: str) -> None:
    """Refuse a map whose wall cells lie wholly outside the plan's extent (with a margin)."""
    ends = segments.reshape(-1, 2)
    low, high = ends.min(axis=0) - _START_M, ends.max(axis=0) + _START_M
    inside = ((cells >= low) & (cells <= high)).all(axis=1)
    if not inside.any():
        msg = (
            f"The map {source!r} (wall cells from {cells.min(axis=0).round(2).tolist()} to "
            f"{cells.max(axis=0).round(2).tolist()} m) and the plan (from "
            f"{ends.min(axis=0).round(2).tolist()} to {ends.max(axis=0).round(2).tolist()} m) "
            "do not overlap; check the site transform, the estimate that places the map "
            "and the plan's units."
        )
        raise MetricError(msg, option="map")


def _figures(d: FloatArray, thresholds_m: Sequence[float], coverage: float | None) -> WallFigures:
    p50, p95 = quantiles(d, [0.5, 0.95])
    return WallFigures(
        rmse=float(np.sqrt(np.mean(d * d))),
        mean=float(d.mean()),
        median=float(p50),
        p95=float(p95),
        max=float(d.max()),
        n=len(d),
        within={float(t): float(np.mean(d <= t)) for t in thresholds_m},
        plan_coverage=coverage,
    )


def _regions(cells: FloatArray, d: FloatArray) -> tuple[dict[str, float | int], ...]:
    """The RMSE of the wall distances per square tile of the plan frame."""
    tiles = np.floor(cells / _REGION_M).astype(np.int64)
    low = tiles.min(axis=0)
    span = int(tiles[:, 1].max() - low[1]) + 1
    flat = (tiles[:, 0] - low[0]) * span + (tiles[:, 1] - low[1])  # one key per tile
    keys, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    sse = np.bincount(inverse.reshape(-1), weights=d * d, minlength=len(keys))
    rmse = np.sqrt(sse / counts)
    centres = (np.column_stack([keys // span, keys % span]) + low + 0.5) * _REGION_M
    return tuple(
        {"x_m": float(x), "y_m": float(y), "size_m": _REGION_M, "n": int(n), "rmse_m": float(r)}
        for (x, y), n, r in zip(centres.tolist(), counts.tolist(), rmse.tolist(), strict=True)
    )


def _warnings(similarity: Fit2D, clutter: int, total: int) -> tuple[str, ...]:
    notes = []
    if clutter > total // 2:
        notes.append(
            f"{clutter} of {total} wall cells are far from every plan wall even after the "
            "best fit: most of the map is not in the plan (another floor, another building "
            "part, or a plan without its furniture)."
        )
    if abs(math.log(similarity.scale)) > 0.1:
        notes.append(
            f"The best similarity fit scales the map by {similarity.scale:.3g}; check the "
            "map's resolution and the plan's units."
        )
    return tuple(notes)


@dataclass(frozen=True, slots=True, eq=False)
class _Coverage:
    """Where the map saw walls and where it mapped, as dilated masks of the grid."""

    grid: OccupancyGrid
    near_wall: BoolArray
    mapped: BoolArray

    @classmethod
    def of(
        cls,
        grid: OccupancyGrid,
        walls: BoolArray,
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
        tolerance_m: float,
    ) -> _Coverage:
        kept = np.zeros_like(walls)
        kept[rows, cols] = True
        reach = max(1, math.ceil(tolerance_m / grid.resolution_m))
        near_wall = maximum_filter(kept, size=2 * reach + 1)
        wide = max(reach, math.ceil(_COVERED_M / grid.resolution_m))
        mapped = maximum_filter(grid.states == FREE, size=2 * wide + 1)
        return cls(grid, near_wall, mapped)

    def share(self, plan_xy: FloatArray) -> float | None:
        """Share of plan samples (map frame) in the mapped area that lie near a wall cell."""
        rows, cols, inside = self.grid.cell_of(plan_xy)
        counted = inside & self.mapped[rows, cols]
        if not counted.any():
            return None
        return float((counted & self.near_wall[rows, cols]).sum() / counted.sum())
