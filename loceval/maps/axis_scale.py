"""Per-axis scale: is the map too long along one of its axes and not the other?

A SLAM map often drifts in length along a corridor and hardly across it (the reference-robot
paper's Fig. 4), which one similarity scale averages away. After the similarity fit, this
fit lets the map's scale differ along its own two grid axes (turned by ``axes_rad`` in the
plan frame), a 5-parameter affine map onto the plan:

    x' = R(θ) R(φ) diag(s_x, s_y) R(-φ) (x - c) + c + t,

estimated, like :func:`loceval.maps.fit.fit_to_plan`, by Gauss-Newton on the point-to-wall
distances of the inlier cells (nearest plan segment, re-found each iteration; inliers
within 3 robust sigmas). Its uncertainty is the Gauss-Newton covariance
``σ² (AᵀA)⁻¹`` with σ² the inliers' residual variance: cells are taken as independent,
so it is a lower bound where the errors are correlated along a wall. A scale along an
axis the plan has no wall across (a single long corridor seen only along its length) is
unobservable; the normal matrix is then near singular and the figure is reported as None.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.core.quantiles import median
from loceval.maps.plan import PlanIndex

__all__ = ["AxisScales", "fit_axis_scales"]

_ITERATIONS: Final = 12
_MIN_KEPT: Final = 20
_MAD_TO_SIGMA: Final = 1.4826
_ON_WALL_M: Final = 1e-7
"""Cells this near a wall take the wall's normal from probes around them."""
_PROBE_M: Final = 1e-4
_CONDITION_MAX: Final = 1e10
"""Normal matrices worse conditioned than this leave an axis scale unobservable."""


@dataclass(frozen=True, slots=True)
class AxisScales:
    """The per-axis scales carrying the map onto the plan, along the map's grid axes.

    Attributes:
        scale_x: the scale along the map's x axis (columns), carrying it onto the plan;
            1 / scale_x is how long the map is along x (1.02: 2 % too long).
        scale_y: the same along y (rows).
        sigma_x: the standard uncertainty of ``scale_x`` (Gauss-Newton, a lower bound).
        sigma_y: the same of ``scale_y``.
        axes_deg: the direction of the map's x axis in the plan frame, degrees.
        kept: inlier cells of the last iteration.
    """

    scale_x: float | None
    scale_y: float | None
    sigma_x: float | None
    sigma_y: float | None
    axes_deg: float
    kept: int

    @staticmethod
    def _pct(scale: float | None) -> float | None:
        return None if scale is None else (1.0 / scale - 1.0) * 100.0

    @property
    def length_error_x_pct(self) -> float | None:
        """How much longer (+) or shorter (-) the map is along its x axis, percent."""
        return self._pct(self.scale_x)

    @property
    def length_error_y_pct(self) -> float | None:
        """How much longer (+) or shorter (-) the map is along its y axis, percent."""
        return self._pct(self.scale_y)

    def times(self, scale: float) -> AxisScales:
        """Return the scales composed with a uniform ``scale`` applied first (the similarity's)."""

        def by(value: float | None) -> float | None:
            return None if value is None else value * scale

        return AxisScales(
            by(self.scale_x),
            by(self.scale_y),
            by(self.sigma_x),
            by(self.sigma_y),
            self.axes_deg,
            self.kept,
        )

    def to_dict(self) -> dict[str, float | int | None]:
        """Return the result document's ``map.axis_scales``."""
        return {
            "scale_x": self.scale_x,
            "scale_y": self.scale_y,
            "sigma_x": self.sigma_x,
            "sigma_y": self.sigma_y,
            "length_error_x_pct": self.length_error_x_pct,
            "length_error_y_pct": self.length_error_y_pct,
            "axes_deg": self.axes_deg,
            "cells_fitted": self.kept,
        }


def fit_axis_scales(
    cells_xy: FloatArray,
    plan: PlanIndex,
    *,
    axes_rad: float,
    start_m: float,
    floor_m: float,
) -> AxisScales | None:
    """Fit the per-axis scales of cells already carried onto the plan by the similarity fit.

    Args:
        cells_xy: (N, 2) the wall cells after the similarity fit, plan frame, metres.
        plan: the indexed plan.
        axes_rad: the direction of the map's x axis in the plan frame.
        start_m: the first inlier distance (a few of the similarity fit's sigmas).
        floor_m: the smallest inlier distance (about a cell).

    Returns:
        The scales relative to the similarity fit's (multiply by its scale for the whole
        map's), or None when too few cells lie near the plan.
    """
    points = np.asarray(cells_xy, dtype=np.float64).reshape(-1, 2)
    a_x = np.array([math.cos(axes_rad), math.sin(axes_rad)])
    a_y = np.array([-a_x[1], a_x[0]])
    matrix = np.eye(2)
    translation = np.zeros(2)
    threshold = float(start_m)
    normal_matrix = np.zeros((5, 5))
    sigma2 = 0.0
    kept = 0
    for _ in range(_ITERATIONS):  # iterations over the whole array, not per cell
        moved = points @ matrix.T + translation
        distance, closest = plan.nearest(moved)
        inlier = distance <= threshold
        kept = int(inlier.sum())
        if kept < _MIN_KEPT:
            return None
        x, r, d = moved[inlier], moved[inlier] - closest[inlier], distance[inlier]
        centre = x.mean(axis=0)
        q = x - centre
        normal = r / np.maximum(d, 1e-12)[:, None]
        flat = d < _ON_WALL_M
        if flat.any():  # on a wall: its residual says nothing of the wall's direction
            normal[flat] = _wall_normals(plan, x[flat])
        columns = np.column_stack(
            [
                normal[:, 0],
                normal[:, 1],
                normal[:, 1] * q[:, 0] - normal[:, 0] * q[:, 1],
                (normal @ a_x) * (q @ a_x),
                (normal @ a_y) * (q @ a_y),
            ]
        )
        b = -np.einsum("ij,ij->i", normal, r)
        normal_matrix = columns.T @ columns
        if np.linalg.cond(normal_matrix) > _CONDITION_MAX:
            return None
        step = np.linalg.solve(normal_matrix, columns.T @ b)
        c, s = math.cos(step[2]), math.sin(step[2])
        stretch = np.eye(2) + step[3] * np.outer(a_x, a_x) + step[4] * np.outer(a_y, a_y)
        update = np.array([[c, -s], [s, c]]) @ stretch
        matrix = update @ matrix
        translation = update @ (translation - centre) + centre + step[:2]
        sigma2 = float(np.sum(d * d)) / max(kept - 5, 1)  # the residuals before this step
        threshold = max(min(threshold, 3.0 * _MAD_TO_SIGMA * median(d)), float(floor_m))
        if np.abs(step).max() < 1e-10:
            break
    covariance = sigma2 * np.linalg.inv(normal_matrix)
    # matrix = R(θ) R(φ) diag(s_x, s_y) R(-φ): its columns along the axes give the scales
    scale_x = float(np.linalg.norm(matrix @ a_x))
    scale_y = float(np.linalg.norm(matrix @ a_y))
    return AxisScales(
        scale_x=scale_x,
        scale_y=scale_y,
        sigma_x=float(math.sqrt(covariance[3, 3])),
        sigma_y=float(math.sqrt(covariance[4, 4])),
        axes_deg=math.degrees(axes_rad),
        kept=kept,
    )


def _wall_normals(plan: PlanIndex, points: FloatArray) -> FloatArray:
    """The unit normals of the walls that points lying on them lie on.

    Moving a point on a wall with normal (a, b) by ε along x, y and the diagonal gives the
    distances ε|a|, ε|b| and ε|a + b|/√2: the magnitudes and whether the signs agree,
    which is all a row of the normal equations needs (n and -n give the same row product).
    """
    probes = np.array([[1.0, 0.0], [0.0, 1.0], [math.sqrt(0.5), math.sqrt(0.5)]]) * _PROBE_M
    moved = (points[:, None, :] + probes[None, :, :]).reshape(-1, 2)
    d = plan.nearest(moved)[0].reshape(-1, 3) / _PROBE_M
    a, b, diagonal = d[:, 0], d[:, 1], d[:, 2]
    same = np.abs(diagonal - (a + b) * math.sqrt(0.5)) <= np.abs(
        diagonal - abs(a - b) * math.sqrt(0.5)
    )
    normal = np.column_stack([a, np.where(same, b, -b)])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    out: FloatArray = normal / np.maximum(length, 1e-12)
    return out
