"""Evaluate an estimate against surveyed control points (the reference-robot paper's §IV).

The estimate's position at a visit is the per-axis median of its own positions over the
visit, taken before the alignment and then transformed by it. The alignment is ``none``
(the estimate is already in building coordinates, as AMCL on the floor plan) or a rigid,
similarity or yaw transform fitted on all visited points or on a chosen subset (the
"stationing" points; the rest are evaluated, as the Hilti SLAM Challenge splits them),
weighted by each point's survey sigma and robust to an outlying point (Huber loss).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from loceval.checkpoints.scores import hilti_score, lamaria_score, recall
from loceval.checkpoints.stops import (
    DEFAULT_STOP_MAX_SPEED_MPS,
    DEFAULT_STOP_MIN_DURATION_S,
    Stop,
    assign_stops,
    find_stops,
    register_stops,
)
from loceval.controlpoints import ControlPoints, Visits
from loceval.core.arrays import BoolArray, FloatArray
from loceval.core.geometry import SimilarityTransform
from loceval.core.rotation import Rotation
from loceval.errors import AlignmentError, InputError
from loceval.metrics.pose_errors import DEFAULT_THRESHOLDS_M, ErrorSeries, ErrorStats, share_within
from loceval.registration.alignment import AlignMethod, align_umeyama, align_yaw
from loceval.trajectory import Trajectory

__all__ = ["CheckpointResult", "VisitResult", "evaluate_checkpoints", "fit_points"]

_NS_PER_S = 1_000_000_000
_HUBER_SCALE = 2.5
"""Residuals beyond 2.5 of their expected sigma pull with a constant force (Huber)."""
_MEDIAN_NORM_3D = 1.5382
"""Median of the norm of a 3D standard normal vector: residual norm -> per-axis sigma."""


@dataclass(frozen=True, slots=True)
class VisitResult:
    """One visit: where the device stood, where the point is, and the error.

    Attributes:
        point_id: the control point.
        start_ns: first stamp of the visit.
        end_ns: last stamp of the visit.
        samples: estimate poses in the visit.
        spread_m: RMS distance of those poses from their median, metres.
        measured_xyz: the aligned median position, metres, building frame.
        surveyed_xyz: the control point.
        used_for_alignment: the visit fixed the alignment and is not scored.
    """

    point_id: str
    start_ns: int
    end_ns: int
    samples: int
    spread_m: float
    measured_xyz: tuple[float, float, float]
    surveyed_xyz: tuple[float, float, float]
    used_for_alignment: bool

    @property
    def error_xyz(self) -> FloatArray:
        """Return measured - surveyed, (3,) metres."""
        return np.subtract(self.measured_xyz, self.surveyed_xyz)

    @property
    def error_m(self) -> float:
        """Return the 3D error, metres."""
        return float(np.linalg.norm(self.error_xyz))

    @property
    def error_h_m(self) -> float:
        """Return the horizontal error, metres."""
        return float(np.hypot(*self.error_xyz[:2]))

    @property
    def error_v_m(self) -> float:
        """Return the signed vertical error (measured minus surveyed height), metres."""
        return float(self.error_xyz[2])

    def to_dict(self) -> dict[str, object]:
        """Return the JSON form (times in seconds on the estimate's clock)."""
        return {
            "id": self.point_id,
            "t_start_s": self.start_ns / _NS_PER_S,
            "t_end_s": self.end_ns / _NS_PER_S,
            "samples": self.samples,
            "spread_m": self.spread_m,
            "measured": list(self.measured_xyz),
            "surveyed": list(self.surveyed_xyz),
            "error_m": self.error_m,
            "error_h_m": self.error_h_m,
            "error_v_m": self.error_v_m,
            "used_for_alignment": self.used_for_alignment,
        }


@dataclass(frozen=True, slots=True, eq=False)
class CheckpointResult:
    """An estimate scored against control points.

    Attributes:
        points: the control points.
        visits: every visit, in time order.
        unvisited: ids of points with no visit.
        unmatched_stops: stops (``--visits auto``) near no control point.
        transform: maps the estimate's frame onto the building's.
        method: the alignment method.
        thresholds_m: the distances of ``within`` and ``recall``.
        warnings: what the user should know.
    """

    points: ControlPoints
    visits: tuple[VisitResult, ...]
    unvisited: tuple[str, ...]
    unmatched_stops: tuple[Stop, ...]
    transform: SimilarityTransform
    method: AlignMethod
    thresholds_m: tuple[float, ...]
    warnings: tuple[str, ...]

    @property
    def scored(self) -> tuple[VisitResult, ...]:
        """Return the visits that are scored (not used for the alignment)."""
        return tuple(v for v in self.visits if not v.used_for_alignment)

    def errors(self) -> ErrorSeries:
        """Return the scored visits' 3D errors, stamped at each visit's start."""
        scored = self.scored
        return ErrorSeries(
            np.array([v.error_m for v in scored]),
            np.array([v.start_ns for v in scored], dtype=np.int64),
            "m",
        )

    def to_dict(self) -> dict[str, object]:
        """Return the estimate entry's ``checkpoints``, ``ate``, ``within`` and ``alignment``."""
        scored = self.scored
        errors = self.errors()
        ids = {pid: k for k, pid in enumerate(self.points.ids)}
        aligned_on = {v.point_id for v in self.visits if v.used_for_alignment}
        counted = np.array([k for pid, k in ids.items() if pid not in aligned_on], dtype=np.int64)
        shares = recall(
            np.array([ids[v.point_id] for v in scored], dtype=np.int64),
            errors.values,
            points=counted,
            thresholds_m=self.thresholds_m,
        )
        return {
            "matched": len(scored),
            "alignment": {"method": self.method.value, **self.transform.to_dict()},
            "ate": {
                "translation_m": errors.stats.to_dict() if len(errors) else None,
                "rotation_deg": None,
            },
            "within": {f"{t:g}": s for t, s in share_within(errors, self.thresholds_m).items()}
            if len(errors)
            else {},
            "checkpoints": {
                "visits": [v.to_dict() for v in self.visits],
                "unvisited": list(self.unvisited),
                "unmatched_stops": [
                    {
                        "t_start_s": s.start_ns / _NS_PER_S,
                        "t_end_s": s.end_ns / _NS_PER_S,
                        "position": list(s.position_xyz),
                    }
                    for s in self.unmatched_stops
                ],
                "score": {
                    "hilti": hilti_score(errors.values),
                    "lamaria": lamaria_score(np.array([v.error_h_m for v in scored])),
                },
                "recall": {f"{t:g}": share for t, share in shares.items()},
            },
            "warnings": list(self.warnings),
        }

    @property
    def stats(self) -> ErrorStats:
        """Return the statistics of the scored visits' 3D errors."""
        return self.errors().stats


def fit_points(
    src_xyz: FloatArray,
    dst_xyz: FloatArray,
    *,
    method: AlignMethod,
    sigma_xyz: FloatArray | None = None,
) -> tuple[SimilarityTransform, BoolArray]:
    """Fit ``dst ~ T(src)`` weighted by each point's sigma, robust to outlying points.

    The closed form (Umeyama, or the planar one for ``yaw``) starts a Huber-loss least
    squares whose residuals are scaled by ``sqrt(sigma_survey² + sigma_estimate²)`` per
    axis, where the estimate's own scatter comes from the closed form's residuals (their
    median norm). A point far off keeps a bounded pull on the result.

    Args:
        src_xyz: (V, 3) measured positions, estimate frame.
        dst_xyz: (V, 3) surveyed positions.
        method: ``se3``, ``sim3`` or ``yaw``.
        sigma_xyz: (V, 3) survey sigmas, metres, or None.

    Returns:
        The transform, and (V,) which points lie beyond five sigma of it (down-weighted).

    Raises:
        AlignmentError: too few points, or points on a line.
    """
    from scipy.optimize import least_squares  # noqa: PLC0415  (only when fitting)

    needed = 2 if method is AlignMethod.YAW else 3
    if len(src_xyz) < needed:
        msg = (
            f"{len(src_xyz)} visits to fit the alignment; {method.value} needs at least "
            f"{needed}; visit more points or use the alignment none."
        )
        raise AlignmentError(msg, option="align")
    start = (
        align_yaw(src_xyz, dst_xyz)
        if method is AlignMethod.YAW
        else align_umeyama(src_xyz, dst_xyz, with_scale=method is AlignMethod.SIM3)
    )
    residual = np.linalg.norm(dst_xyz - start.apply_positions(src_xyz), axis=1)
    sigma_est = float(np.median(residual)) / _MEDIAN_NORM_3D
    survey = np.zeros_like(src_xyz) if sigma_xyz is None else sigma_xyz
    scale_xyz = np.sqrt(survey**2 + sigma_est**2)
    scale_xyz = np.maximum(scale_xyz, 1e-6)  # a perfect fit: keep the residuals finite
    centre = src_xyz.mean(axis=0)

    def unpack(params: FloatArray) -> SimilarityTransform:
        if method is AlignMethod.YAW:
            rot = Rotation.from_euler("z", params[0]).as_matrix()
            shift, scale = params[1:4], 1.0
        else:
            rot = Rotation.from_rotvec(params[:3]).as_matrix()
            shift = params[3:6]
            scale = float(np.exp(params[6])) if method is AlignMethod.SIM3 else 1.0
        # Parametrised about the centroid, so rotation and translation are not coupled.
        return SimilarityTransform(rot, shift - scale * rot @ centre, scale)

    def residuals(params: FloatArray) -> FloatArray:
        out: FloatArray = ((unpack(params).apply_positions(src_xyz) - dst_xyz) / scale_xyz).ravel()
        return out

    rot0 = Rotation.from_matrix(start.rotation)
    shift0 = start.apply_positions(centre)
    if method is AlignMethod.YAW:
        yaw0 = np.arctan2(start.rotation[1, 0], start.rotation[0, 0])
        x0 = np.concatenate([[yaw0], shift0])
    else:
        x0 = np.concatenate([rot0.as_rotvec(), shift0])
        if method is AlignMethod.SIM3:
            x0 = np.append(x0, np.log(start.scale))
    fit = least_squares(residuals, x0, loss="huber", f_scale=_HUBER_SCALE, x_scale="jac")
    transform = unpack(fit.x)
    normalised = np.abs((transform.apply_positions(src_xyz) - dst_xyz) / scale_xyz).max(axis=1)
    return transform, normalised > 5.0


def _median_positions(
    estimate: Trajectory, start_ns: np.ndarray, end_ns: np.ndarray
) -> tuple[FloatArray, np.ndarray, FloatArray]:
    """Per window: the per-axis median position, the sample count and the RMS spread."""
    lo = np.searchsorted(estimate.stamps_ns, start_ns, side="left")
    hi = np.searchsorted(estimate.stamps_ns, end_ns, side="right")
    medians = np.full((len(lo), 3), np.nan)
    spread = np.full(len(lo), np.nan)
    for k, (a, b) in enumerate(zip(lo, hi, strict=True)):  # one iteration per visit
        if b > a:
            window = estimate.positions_xyz[a:b]
            medians[k] = np.median(window, axis=0)
            spread[k] = float(np.sqrt(((window - medians[k]) ** 2).sum(axis=1).mean()))
    return medians, hi - lo, spread


def _visits_in_range(visits: Visits, estimate: Trajectory, points: ControlPoints) -> None:
    first, last = int(estimate.stamps_ns[0]), int(estimate.stamps_ns[-1])
    outside = np.flatnonzero((visits.end_ns < first) | (visits.start_ns > last))
    if outside.size:
        k = int(outside[0])
        msg = (
            f"{outside.size} of {len(visits)} visits lie outside the estimate's time range "
            f"({first / _NS_PER_S:.3f}-{last / _NS_PER_S:.3f} s), e.g. point "
            f"{points.ids[visits.point_index[k]]!r} at {visits.start_ns[k] / _NS_PER_S:.3f} s; "
            "give the visits in seconds on the estimate's clock."
        )
        raise InputError(msg, option="visits")


def _auto_visits(
    estimate: Trajectory,
    points: ControlPoints,
    *,
    method: AlignMethod,
    align_ids: Sequence[str],
    radius_m: float,
    max_speed_mps: float,
    min_duration_s: float,
) -> tuple[Visits, list[Stop], SimilarityTransform | None]:
    """Find the stops and the point each stands on; also the placement used to assign them."""
    stops = find_stops(estimate, max_speed_mps=max_speed_mps, min_duration_s=min_duration_s)
    if not stops:
        msg = (
            f"No stationary period found in {estimate.name or 'the estimate'}: it never "
            f"stayed below {max_speed_mps:g} m/s for {min_duration_s:g} s; raise the stop "
            "speed threshold, lower the minimum stop duration, or give a visits file."
        )
        raise InputError(msg, option="visits")
    stops_xyz = np.array([s.position_xyz for s in stops])
    placement = None
    if method is not AlignMethod.NONE:
        if align_ids:
            # Stationing: the first stops are the alignment points, in the order named.
            if len(stops) < len(align_ids):
                msg = (
                    f"{len(stops)} stops found but {len(align_ids)} alignment points named; "
                    "the first stops must be the alignment points, in the order named."
                )
                raise InputError(msg, option="align_points")
            index = points.index_of(list(align_ids), where="The alignment points")
            placement, _ = fit_points(
                stops_xyz[: len(align_ids)], points.positions_xyz[index], method=method
            )
        else:
            placement = register_stops(
                stops_xyz, points.positions_xyz, method=method, radius_m=radius_m
            )
        stops_xyz = placement.apply_positions(stops_xyz)
    assigned = assign_stops(stops_xyz, points.positions_xyz, radius_m=radius_m)
    if align_ids and placement is not None:
        assigned[: len(align_ids)] = points.index_of(list(align_ids), where="The alignment points")
    hit = assigned >= 0
    visits = Visits(
        assigned[hit],
        np.array([s.start_ns for s, h in zip(stops, hit, strict=True) if h], dtype=np.int64),
        np.array([s.end_ns for s, h in zip(stops, hit, strict=True) if h], dtype=np.int64),
        source="auto",
    )
    unmatched = [s for s, h in zip(stops, hit, strict=True) if not h]
    return visits, unmatched, placement


def evaluate_checkpoints(
    points: ControlPoints,
    estimate: Trajectory,
    *,
    visits: Visits | None = None,
    method: AlignMethod = AlignMethod.NONE,
    align_points: Sequence[str] = (),
    visit_radius_m: float | None = None,
    stop_max_speed_mps: float = DEFAULT_STOP_MAX_SPEED_MPS,
    stop_min_duration_s: float = DEFAULT_STOP_MIN_DURATION_S,
    thresholds_m: Sequence[float] = DEFAULT_THRESHOLDS_M,
) -> CheckpointResult:
    """Score ``estimate`` against ``points`` at its visits.

    Args:
        points: the surveyed control points.
        estimate: the system under test.
        visits: when the device stood on which point; None finds them (stops).
        method: ``none``, ``se3``, ``sim3`` or ``yaw``.
        align_points: ids of the points that fix the alignment (the rest are scored);
            empty: all visited points fix it and all are scored.
        visit_radius_m: how near a stop must be to a point to visit it (default half the
            smallest distance between two points).
        stop_max_speed_mps: stops: the speed below which the device stands still.
        stop_min_duration_s: stops: how long it must stand still.
        thresholds_m: distances of the "share within" and recall figures.

    Returns:
        The visits, their errors and the scores.

    Raises:
        InputError: a visit outside the estimate's time range, no stop found, an unknown
            alignment point, or no visit with samples.
        AlignmentError: the alignment is undetermined or ambiguous.
    """
    if method not in {AlignMethod.NONE, AlignMethod.SE3, AlignMethod.SIM3, AlignMethod.YAW}:
        msg = f"Control points are aligned with none, se3, sim3 or yaw, not {method.value!r}."
        raise InputError(msg, option="align")
    radius = points.min_spacing_m() / 2 if visit_radius_m is None else visit_radius_m
    if not (np.isfinite(radius) and radius > 0):
        msg = f"The visit radius must be positive metres, got {radius!r}."
        raise InputError(msg, option="visit_radius_m")
    align_ids = list(dict.fromkeys(align_points))
    align_index = points.index_of(align_ids, where="The alignment points")
    notes: list[str] = []
    unmatched: list[Stop] = []
    if visits is None:
        visits, unmatched, _ = _auto_visits(
            estimate,
            points,
            method=method,
            align_ids=align_ids,
            radius_m=radius,
            max_speed_mps=stop_max_speed_mps,
            min_duration_s=stop_min_duration_s,
        )
        if unmatched:
            notes.append(
                f"{len(unmatched)} stops are farther than {radius:g} m from every control "
                "point and were not scored (listed as unmatched stops)."
            )
    else:
        _visits_in_range(visits, estimate, points)
    measured, samples, spread = _median_positions(estimate, visits.start_ns, visits.end_ns)
    empty = samples == 0
    if empty.any():
        notes.append(
            f"{int(empty.sum())} visits have no estimate pose (tracking loss) and were not scored."
        )
    keep = ~empty
    if not keep.any():
        msg = "No visit has an estimate pose in it; check the visit times and the estimate."
        raise InputError(msg, option="visits")
    point_index = visits.point_index[keep]
    measured, samples, spread = measured[keep], samples[keep], spread[keep]
    surveyed = points.positions_xyz[point_index]
    for_alignment = (
        np.isin(point_index, align_index) if align_ids else np.ones(len(point_index), bool)
    )
    transform = SimilarityTransform.identity()
    if method is not AlignMethod.NONE:
        sigma = None if points.sigma_xyz is None else points.sigma_xyz[point_index]
        transform, far = fit_points(
            measured[for_alignment],
            surveyed[for_alignment],
            method=method,
            sigma_xyz=None if sigma is None else sigma[for_alignment],
        )
        if far.any():
            off = sorted({points.ids[k] for k in point_index[for_alignment][far]})
            notes.append(
                f"Control points {', '.join(off)} lie far from the fitted alignment and were "
                "down-weighted; check their survey or the visits."
            )
    used = for_alignment if align_ids else np.zeros(len(point_index), bool)
    aligned = transform.apply_positions(measured)
    results = tuple(
        VisitResult(
            point_id=points.ids[int(k)],
            start_ns=int(a),
            end_ns=int(b),
            samples=int(n),
            spread_m=float(s),
            measured_xyz=(float(m[0]), float(m[1]), float(m[2])),
            surveyed_xyz=(float(p[0]), float(p[1]), float(p[2])),
            used_for_alignment=bool(u),
        )
        for k, a, b, n, s, m, p, u in zip(
            point_index,
            visits.start_ns[keep],
            visits.end_ns[keep],
            samples,
            spread,
            aligned,
            surveyed,
            used,
            strict=True,
        )
    )
    if not any(not v.used_for_alignment for v in results):
        msg = (
            "Every visit is of an alignment point, so none is left to score; name fewer "
            "alignment points."
        )
        raise InputError(msg, option="align_points")
    visited = set(point_index.tolist())
    unvisited = tuple(pid for k, pid in enumerate(points.ids) if k not in visited)
    return CheckpointResult(
        points=points,
        visits=results,
        unvisited=unvisited,
        unmatched_stops=tuple(unmatched),
        transform=transform,
        method=method,
        thresholds_m=tuple(float(t) for t in thresholds_m),
        warnings=tuple(notes),
    )
