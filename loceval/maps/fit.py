"""Robust 2D fits of a map's wall cells onto a plan: rigid (x, y, yaw) and similarity (+ scale).

The fit is an iteratively reweighted, trimmed point-to-line ICP. Each iteration measures
every cell against the plan (:class:`~loceval.maps.plan.PlanIndex`), keeps the cells
within a threshold that shrinks from the clutter distance to three robust standard
deviations of the kept residuals (never below a cell), and solves the linearised
point-to-line least squares for a small rotation, scale and translation about the kept
cells' centroid (a Gauss-Newton step with a little damping, so a direction no wall
constrains, along a straight corridor, stays put instead of running off). Point-to-line
residuals let cells slide along their wall, which is why it converges in a few steps where
point-to-point ICP crawls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.core.geometry import SimilarityTransform
from loceval.core.quantiles import median
from loceval.errors import MetricError
from loceval.maps.plan import PlanIndex

__all__ = ["Fit2D", "fit_to_plan"]

_ITERATIONS: Final = 40
_MIN_KEPT: Final = 10
_DAMPING: Final = 1e-6
_MAD_TO_SIGMA: Final = 1.4826


@dataclass(frozen=True, slots=True)
class Fit2D:
    """``p -> scale * R(rotation_rad) @ p + translation_m`` in the plane.

    Attributes:
        scale: the scale (1 for a rigid fit).
        rotation_rad: counter-clockwise rotation, radians.
        translation_m: (x, y) translation, metres.
        kept: how many cells the last iteration kept (inliers).
        iterations: iterations run.
    """

    scale: float = 1.0
    rotation_rad: float = 0.0
    translation_m: tuple[float, float] = (0.0, 0.0)
    kept: int = 0
    iterations: int = 0

    def apply(self, xy: FloatArray) -> FloatArray:
        """Map (N, 2) points."""
        c, s = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        out: FloatArray = self.scale * (xy @ np.array([[c, s], [-s, c]])) + np.asarray(
            self.translation_m
        )
        return out

    def inverse_apply(self, xy: FloatArray) -> FloatArray:
        """Map (N, 2) points back: the inverse of :meth:`apply`."""
        c, s = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        moved = (xy - np.asarray(self.translation_m)) / self.scale
        out: FloatArray = moved @ np.array([[c, -s], [s, c]])
        return out

    def as_transform(self) -> SimilarityTransform:
        """Return the fit as a 3D similarity about the z axis."""
        c, s = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return SimilarityTransform(rotation, np.array([*self.translation_m, 0.0]), self.scale)

    def to_dict(self) -> dict[str, object]:
        """Return scale, rotation_deg and translation_m for the result document."""
        return {
            "scale": self.scale,
            "rotation_deg": math.degrees(self.rotation_rad),
            "translation_m": list(self.translation_m),
        }


def fit_to_plan(
    cells_xy: FloatArray,
    plan: PlanIndex,
    *,
    with_scale: bool,
    start_m: float,
    floor_m: float,
) -> Fit2D:
    """Fit cells onto the plan, robustly.

    Args:
        cells_xy: (N, 2) the wall cells, placed in the plan's frame, metres.
        plan: the indexed plan.
        with_scale: fit a similarity (else rigid).
        start_m: the first iteration's inlier distance (the clutter distance).
        floor_m: the smallest inlier distance (about a cell).

    Returns:
        The transform carrying the cells onto the plan.

    Raises:
        MetricError: too few cells lie near the plan to fit (no overlap).
    """
    points = np.asarray(cells_xy, dtype=np.float64).reshape(-1, 2)
    fit = Fit2D()
    threshold = float(start_m)
    kept = 0
    iterations = 0
    for _ in range(_ITERATIONS):  # iterations over the whole array, not per cell
        iterations += 1
        moved = fit.apply(points)
        distance, closest = plan.nearest(moved)
        inlier = distance <= threshold
        kept = int(inlier.sum())
        if kept < _MIN_KEPT:
            msg = (
                f"Only {kept} of the map's {len(points)} wall cells lie within {threshold:g} m "
                "of a plan wall, too few to fit the map onto the plan; check that the map and "
                "the plan overlap (the estimate's alignment or the site transform places them)."
            )
            raise MetricError(msg, option="map")
        step = _step(moved[inlier], closest[inlier], distance[inlier], with_scale=with_scale)
        fit = _compose(step, fit)
        sigma = _MAD_TO_SIGMA * median(distance[inlier])
        threshold = max(min(threshold, 3.0 * sigma), float(floor_m))
        if abs(step[0]) < 1e-9 and abs(step[1]) < 1e-9 and np.hypot(*step[2]) < 1e-7:
            break
    return Fit2D(fit.scale, fit.rotation_rad, fit.translation_m, kept, iterations)


def _step(
    x: FloatArray, closest: FloatArray, distance: FloatArray, *, with_scale: bool
) -> tuple[float, float, FloatArray, FloatArray]:
    """One Gauss-Newton step: (d_scale, d_rotation, d_translation, centre)."""
    centre = x.mean(axis=0)
    r = x - closest
    normal = r / np.maximum(distance, 1e-12)[:, None]
    flat = distance < 1e-9  # on the wall: any normal gives a zero residual; drop its row
    normal[flat] = 0.0
    q = x - centre
    columns = [normal[:, 0], normal[:, 1], normal[:, 0] * -q[:, 1] + normal[:, 1] * q[:, 0]]
    if with_scale:
        columns.append(np.einsum("ij,ij->i", normal, q))
    a = np.column_stack(columns)
    b = -np.einsum("ij,ij->i", normal, r)
    ata = a.T @ a
    ata += _DAMPING * max(float(np.trace(ata)), 1e-12) * np.eye(len(columns))
    solution = np.linalg.solve(ata, a.T @ b)
    d_scale = float(solution[3]) if with_scale else 0.0
    return d_scale, float(solution[2]), solution[:2], centre


def _compose(step: tuple[float, float, FloatArray, FloatArray], fit: Fit2D) -> Fit2D:
    """Apply ``x -> (1 + ds) R(dθ) (x - c) + c + dt`` after ``fit``."""
    d_scale, d_rot, d_t, centre = step
    factor = 1.0 + d_scale
    c, s = math.cos(d_rot), math.sin(d_rot)
    rot = np.array([[c, -s], [s, c]])
    t = factor * rot @ (np.asarray(fit.translation_m) - centre) + centre + d_t
    return Fit2D(fit.scale * factor, fit.rotation_rad + d_rot, (float(t[0]), float(t[1])))
