"""Where a device stood still, and which control point it stood on.

:func:`find_stops` finds the stationary periods of a trajectory: the speed, measured as the
displacement over a short window (so that a few millimetres of noise at 30 Hz do not look
like motion), stays below a threshold for at least a minimum time. :func:`assign_stops`
gives each stop the nearest control point within a radius. When the estimate is not in
the building's frame, :func:`register_stops` first finds the rigid (or similarity)
transform that puts the most stops on control points, and refuses to guess when a
symmetric layout (a grid) fits several ways equally well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import FloatArray, IntArray, StampsNs
from loceval.core.geometry import SimilarityTransform
from loceval.errors import AlignmentError, InputError
from loceval.registration.alignment import AlignMethod, align_umeyama, align_yaw
from loceval.trajectory import Trajectory

__all__ = [
    "DEFAULT_STOP_MAX_SPEED_MPS",
    "DEFAULT_STOP_MIN_DURATION_S",
    "Stop",
    "assign_stops",
    "find_stops",
    "register_stops",
]

_NS_PER_S = 1_000_000_000

DEFAULT_STOP_MAX_SPEED_MPS = 0.05
"""A person standing on a mark sways by a centimetre or two a second; walking is 1.2 m/s, a
slow robot 0.2 m/s."""
DEFAULT_STOP_MIN_DURATION_S = 1.0
"""Short enough for a robot that pauses on each mark, long enough to skip turning points."""
_SPEED_WINDOW_S = 0.5
"""The speed compares the mean position of the half second before each pose with that of the
half second after it: at 30 Hz, 1 cm of noise per pose gives about 0.007 m/s."""


@dataclass(frozen=True, slots=True)
class Stop:
    """A stationary period of the estimate.

    Attributes:
        start_ns: first stamp, inclusive.
        end_ns: last stamp, inclusive.
        samples: estimate poses in it.
        position_xyz: per-axis median of its positions, estimate frame.
    """

    start_ns: int
    end_ns: int
    samples: int
    position_xyz: tuple[float, float, float]


def find_stops(
    trajectory: Trajectory,
    *,
    max_speed_mps: float = DEFAULT_STOP_MAX_SPEED_MPS,
    min_duration_s: float = DEFAULT_STOP_MIN_DURATION_S,
    max_gap_ns: int | None = None,
) -> list[Stop]:
    """Return the stationary periods of ``trajectory``, in time order.

    The speed at each pose is the distance between the mean positions of the half second
    before and the half second after it, over the time between them; a stop is a run of poses
    below ``max_speed_mps`` lasting at least ``min_duration_s``, never spanning a gap in
    the trajectory longer than ``max_gap_ns`` (default: five median intervals).

    Raises:
        InputError: a threshold is not positive.
    """
    if not (np.isfinite(max_speed_mps) and max_speed_mps > 0):
        msg = f"The stop speed threshold must be positive m/s, got {max_speed_mps!r}."
        raise InputError(msg, option="stop_max_speed_mps")
    if not (np.isfinite(min_duration_s) and min_duration_s > 0):
        msg = f"The minimum stop duration must be positive seconds, got {min_duration_s!r}."
        raise InputError(msg, option="stop_min_duration_s")
    stamps = trajectory.stamps_ns
    speed = _window_speed(stamps, trajectory.positions_xyz, _SPEED_WINDOW_S)
    xyz = trajectory.positions_xyz
    still = speed < max_speed_mps
    steps = np.diff(stamps)
    if max_gap_ns is None:
        max_gap_ns = int(5 * np.median(steps)) if steps.size else 0
    breaks = np.flatnonzero(steps > max_gap_ns) + 1  # a run may not cross these
    edges = np.diff(np.concatenate(([0], still.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)  # exclusive
    # Split runs at gaps: every break inside a run ends one run and starts the next.
    cut = breaks[still[breaks] & still[breaks - 1]] if breaks.size else breaks
    starts = np.sort(np.concatenate([starts, cut]))
    ends = np.sort(np.concatenate([ends, cut]))
    min_ns = round(min_duration_s * _NS_PER_S)
    stops = []
    for a, b in zip(starts, ends, strict=True):  # one iteration per stationary run
        if stamps[b - 1] - stamps[a] < min_ns:
            continue
        median = np.median(xyz[a:b], axis=0)
        stops.append(
            Stop(
                start_ns=int(stamps[a]),
                end_ns=int(stamps[b - 1]),
                samples=int(b - a),
                position_xyz=(float(median[0]), float(median[1]), float(median[2])),
            )
        )
    return stops


def _window_speed(stamps_ns: StampsNs, xyz: FloatArray, window_s: float) -> FloatArray:
    """Speed at each pose: mean position after minus mean position before, over their times.

    Both means come from prefix sums, so this is O(N) whatever the window.
    """
    t = (stamps_ns - stamps_ns[0]).astype(np.float64) / _NS_PER_S
    csum = np.vstack([np.zeros((1, 3)), np.cumsum(xyz, axis=0)])
    tsum = np.concatenate([[0.0], np.cumsum(t)])
    k = np.arange(len(t))
    lo = np.searchsorted(t, t - window_s, side="left")
    hi = np.searchsorted(t, t + window_s, side="right")
    n_before = np.maximum(k + 1 - lo, 1)  # [lo, k]
    n_after = np.maximum(hi - k, 1)  # [k, hi)
    mean_before = (csum[k + 1] - csum[lo]) / n_before[:, None]
    mean_after = (csum[hi] - csum[k]) / n_after[:, None]
    dt = (tsum[hi] - tsum[k]) / n_after - (tsum[k + 1] - tsum[lo]) / n_before
    speed: FloatArray = np.linalg.norm(mean_after - mean_before, axis=1) / np.maximum(dt, 1e-3)
    return speed


def _nearest(points_xyz: FloatArray, query_xyz: FloatArray) -> tuple[IntArray, FloatArray]:
    """Return the nearest point's index and distance for each query, (Q,) each."""
    if query_xyz.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    dist = np.linalg.norm(query_xyz[:, None, :] - points_xyz[None, :, :], axis=2)
    index = dist.argmin(axis=1)
    return index.astype(np.int64), dist[np.arange(len(query_xyz)), index]


def assign_stops(stops_xyz: FloatArray, points_xyz: FloatArray, *, radius_m: float) -> IntArray:
    """Return the nearest control point of each stop, or -1 beyond ``radius_m``.

    Args:
        stops_xyz: (S, 3) stop positions in the control points' frame.
        points_xyz: (N, 3) control points.
        radius_m: the largest distance at which a stop counts as a visit.
    """
    index, dist = _nearest(points_xyz, stops_xyz)
    return np.where(dist <= radius_m, index, -1)


def _fit(src: FloatArray, dst: FloatArray, method: AlignMethod) -> SimilarityTransform | None:
    try:
        if method is AlignMethod.YAW:
            return align_yaw(src, dst)
        return align_umeyama(src, dst, with_scale=method is AlignMethod.SIM3)
    except AlignmentError:
        return None


def _base_triplets(stops_xyz: FloatArray, count: int, rng: np.random.Generator) -> list[IntArray]:
    """Spread-out stop triplets to hypothesise from: the widest first, then random ones."""
    centre = stops_xyz.mean(axis=0)
    a = int(np.argmax(np.linalg.norm(stops_xyz - centre, axis=1)))
    b = int(np.argmax(np.linalg.norm(stops_xyz - stops_xyz[a], axis=1)))
    ab = stops_xyz[b] - stops_xyz[a]
    rel = stops_xyz - stops_xyz[a]
    off_line = np.linalg.norm(np.cross(rel, ab), axis=1)
    c = int(np.argmax(off_line))
    spread = [rng.choice(len(stops_xyz), size=3, replace=False) for _ in range(count - 1)]
    return [np.array([a, b, c]), *spread]


def register_stops(
    stops_xyz: FloatArray,
    points_xyz: FloatArray,
    *,
    method: AlignMethod,
    radius_m: float,
    seed: int = 0,
) -> SimilarityTransform:
    """Find the transform that puts the most stops on control points.

    Hypotheses come from triplets of stops matched to triplets of control points whose
    side lengths agree within the radius (scaled for ``sim3``); each is scored by the
    number of stops that land within ``radius_m`` of a control point. The best wins unless
    a clearly different transform (it moves some stop by more than the radius) scores
    within 5 % of it: then the layout is symmetric and the visits cannot be told apart.

    Raises:
        AlignmentError: fewer than 3 stops, no hypothesis places 3 stops, or the fit is
            ambiguous (the message says how to settle it).
    """
    s = len(stops_xyz)
    if s < 3:
        msg = (
            f"{s} stops found; finding the visits automatically in another frame needs at "
            "least 3; give a visits file."
        )
        raise AlignmentError(msg, option="visits")
    from scipy.spatial import cKDTree  # noqa: PLC0415  (heavy; only for this search)

    rng = np.random.default_rng(seed)
    pd = np.linalg.norm(points_xyz[:, None] - points_xyz[None], axis=2)  # (N, N)
    transforms: list[SimilarityTransform] = []
    for tri in _base_triplets(stops_xyz, 4, rng):
        d01, d02, d12 = (
            float(np.linalg.norm(stops_xyz[tri[i]] - stops_xyz[tri[j]]))
            for i, j in ((0, 1), (0, 2), (1, 2))
        )
        if min(d01, d02) < radius_m:
            continue
        pa, pb = np.nonzero(pd > 0)  # every ordered pair of distinct points
        scale = pd[pa, pb] / d01 if method is AlignMethod.SIM3 else np.ones(pa.size)
        keep = np.abs(pd[pa, pb] - scale * d01) <= 2 * radius_m
        pa, pb, scale = pa[keep], pb[keep], scale[keep]
        # Third point: its distances to a and b match the stops' (all pairs x points).
        ok = (np.abs(pd[pa][:, :] - scale[:, None] * d02) <= 2 * radius_m) & (
            np.abs(pd[pb][:, :] - scale[:, None] * d12) <= 2 * radius_m
        )
        pair, pc = np.nonzero(ok)
        src = stops_xyz[tri]
        for k, c in zip(pair, pc, strict=True):  # one iteration per hypothesis
            dst = points_xyz[[pa[k], pb[k], c]]
            transform = _fit(src, dst, method)
            if transform is not None:
                transforms.append(transform)
    if not transforms:
        msg = (
            "No placement of the stops fits the control points; check that the estimate "
            "stopped on them, or give a visits file."
        )
        raise AlignmentError(msg, option="visits")
    rotations = np.stack([t.rotation * t.scale for t in transforms])  # (H, 3, 3)
    shifts = np.stack([t.translation for t in transforms])  # (H, 3)
    placed = np.einsum("hij,sj->hsi", rotations, stops_xyz) + shifts[:, None, :]  # (H, S, 3)
    nearest_m = np.asarray(cKDTree(points_xyz).query(placed.reshape(-1, 3))[0], dtype=np.float64)
    dist = nearest_m.reshape(placed.shape[:2])
    hits = (dist <= radius_m).sum(axis=1)
    cost = np.where(dist <= radius_m, dist, radius_m).sum(axis=1)
    best = int(np.lexsort((cost, -hits))[0])
    close = hits >= hits[best] - max(1, int(np.ceil(0.05 * hits[best])))
    moved = np.linalg.norm(placed - placed[best], axis=2).max(axis=1) > radius_m
    rivals = np.flatnonzero(close & moved)
    if rivals.size:
        msg = (
            f"The stops fit the control points in {1 + _distinct(placed[rivals], radius_m)} "
            f"ways about equally well ({hits[best]} of {s} stops on points), as a symmetric "
            "layout such as a grid does; give a visits file, or stand on the alignment "
            "points first and name them in the order visited, instead of letting it guess."
        )
        raise AlignmentError(msg, option="visits")
    return transforms[best]


def _distinct(placed: FloatArray, radius_m: float) -> int:
    """Count clusters of placements that differ by more than the radius."""
    reps: list[FloatArray] = []
    for p in placed:  # a handful of rival hypotheses
        if all(np.linalg.norm(p - r, axis=1).max() > radius_m for r in reps):
            reps.append(p)
    return len(reps)


def stop_windows(stops: list[Stop]) -> tuple[StampsNs, StampsNs]:
    """Return the stops' start and end stamps, (S,) each."""
    return (
        np.array([s.start_ns for s in stops], dtype=np.int64),
        np.array([s.end_ns for s in stops], dtype=np.int64),
    )
