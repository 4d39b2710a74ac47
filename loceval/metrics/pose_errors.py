"""Error metrics: ATE, RPE, drift, statistics, CDF, thresholds and the greatest errors.

Every error series is a plain array with the stamps it belongs to, and its statistics are
the reference-system paper's Pathcompare set (rmse, mean, median, std, var, min, max, sse,
n). ``std`` and ``var`` are population figures (``rmse² = mean² + std²``), as in the
TUM tools and evo.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

import numpy as np

from loceval.core.arrays import FloatArray, IntArray, StampsNs
from loceval.core.geometry import compose_quat, conjugate_quat, relative_angle_deg
from loceval.core.norms import row_norms
from loceval.core.quantiles import median as median_of
from loceval.core.rotation import Rotation
from loceval.errors import MetricError
from loceval.options import DEFAULT_THRESHOLDS_M, RPEUnit
from loceval.trajectory import Trajectory

__all__ = [
    "DEFAULT_THRESHOLDS_M",
    "WORST_SEPARATION_S",
    "ErrorSeries",
    "ErrorStats",
    "RPEUnit",
    "WorstPose",
    "compute_ate",
    "compute_drift",
    "compute_rpe",
    "drift_segment_lengths_m",
    "greatest_errors",
    "rpe_pairs",
    "share_within",
]


_NS_PER_S = 1_000_000_000
_MIN_RPE_DELTA = {RPEUnit.SECONDS: 1e-6, RPEUnit.METRES: 1e-6}
"""The least RPE delta whatever the data: a microsecond, a micrometre."""


@dataclass(frozen=True, slots=True)
class ErrorStats:
    """Summary statistics of an error series (the reference-system paper's Pathcompare)."""

    rmse: float
    mean: float
    median: float
    std: float
    var: float
    min: float
    max: float
    sse: float
    n: int

    @classmethod
    def of(cls, values: FloatArray) -> ErrorStats:
        """Return the statistics of ``values`` (N,).

        Raises:
            MetricError: the series is empty.
        """
        if values.size == 0:
            msg = "No errors to summarize; the evaluation matched no poses for this metric."
            raise MetricError(msg)
        sse = float(np.dot(values, values))
        mean = float(values.mean())
        var = float(values.var())
        return cls(
            rmse=float(np.sqrt(sse / values.size)),
            mean=mean,
            median=median_of(values),
            std=float(np.sqrt(var)),
            var=var,
            min=float(values.min()),
            max=float(values.max()),
            sse=sse,
            n=int(values.size),
        )

    def to_dict(self) -> dict[str, float | int]:
        """Return the statistics as ``{"rmse", "mean", ..., "n"}``."""
        return {
            "rmse": self.rmse,
            "mean": self.mean,
            "median": self.median,
            "std": self.std,
            "var": self.var,
            "min": self.min,
            "max": self.max,
            "sse": self.sse,
            "n": self.n,
        }


@dataclass(frozen=True, slots=True, eq=False)
class ErrorSeries:
    """Errors with the stamps they belong to.

    Attributes:
        values: (N,) errors (metres, degrees or percent: see ``unit``).
        stamps_ns: (N,) stamps; for RPE and drift, the stamp of the pair's first pose.
        unit: "m", "deg" or "%".
    """

    values: FloatArray
    stamps_ns: StampsNs
    unit: str
    # the statistics, computed on first use: every table, report and CI file of a run asks
    # for them again (seven times each in a report's table), and the values are read-only
    _stats: ErrorStats | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        """Make the arrays read-only copies."""
        values = np.array(self.values, dtype=np.float64)
        stamps = np.array(self.stamps_ns, dtype=np.int64)
        values.flags.writeable = False
        stamps.flags.writeable = False
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "stamps_ns", stamps)

    def __len__(self) -> int:
        """Return the number of errors."""
        return int(self.values.shape[0])

    @property
    def stats(self) -> ErrorStats:
        """Return the summary statistics (computed once)."""
        stats = self._stats
        if stats is None:
            stats = ErrorStats.of(self.values)
            object.__setattr__(self, "_stats", stats)
        return stats

    def cdf(self) -> tuple[FloatArray, FloatArray]:
        """Return the empirical CDF: sorted errors and the share of errors ≤ each, (N,)."""
        sorted_values = np.sort(self.values)
        shares = np.arange(1, sorted_values.size + 1, dtype=np.float64) / sorted_values.size
        return sorted_values, shares


@dataclass(frozen=True, slots=True)
class WorstPose:
    """One of the greatest errors: where and when.

    Attributes:
        stamp_ns: stamp of the pose.
        t_s: seconds since the reference's first pose.
        error: the error (metres).
        position_xyz: the reference position there, metres.
        index: index in the matched series.
    """

    stamp_ns: int
    t_s: float
    error: float
    position_xyz: tuple[float, float, float]
    index: int

    def to_dict(self) -> dict[str, object]:
        """Return the JSON form."""
        return {
            "stamp_ns": self.stamp_ns,
            "t_s": self.t_s,
            "error_m": self.error,
            "position": list(self.position_xyz),
            "index": self.index,
        }


def compute_ate(
    reference: Trajectory, aligned: Trajectory
) -> tuple[ErrorSeries, ErrorSeries | None]:
    """Absolute trajectory error per matched pose.

    The framework paper's eq. 1, ``F_i = Q_i^-1 S P_i``: its translation norm (metres) and,
    when both sides have orientations, its rotation angle (degrees).

    Args:
        reference: matched reference poses Q.
        aligned: matched estimate poses already mapped by the alignment S.

    Returns:
        Translation errors and rotation errors (None for position-only sources).
    """
    _require_matched(reference, aligned)
    translation = row_norms(aligned.positions_xyz - reference.positions_xyz)
    ate_t = ErrorSeries(translation, reference.stamps_ns, "m")
    if reference.quat_xyzw is None or aligned.quat_xyzw is None:
        return ate_t, None
    angles = relative_angle_deg(reference.quat_xyzw, aligned.quat_xyzw)
    return ate_t, ErrorSeries(angles, reference.stamps_ns, "deg")


def rpe_pairs(
    reference: Trajectory, *, delta: float, unit: RPEUnit, all_pairs: bool = False
) -> tuple[IntArray, IntArray]:
    """Index pairs ``(i, j)`` for the relative pose error.

    Frames: ``j = i + delta``. Metres and seconds: ``j`` is the first pose at least
    ``delta`` metres travelled (on the reference) or seconds after ``i``. Without
    ``all_pairs`` the pairs are consecutive, non-overlapping segments starting at the first
    pose (each pair starts where the last one ended), as KITTI and evo do; with it, every
    pose starts a pair.

    Every pair spans at least one step (``j > i``), so there are at most N - 1 pairs
    whatever the delta; a delta in seconds below the reference's median sampling interval,
    or in metres below its median step (of the steps that move), is refused: such a pair
    would not measure a step at all (and a delta that rounds to nothing would pair a pose
    with itself).

    Raises:
        MetricError: ``delta`` is not positive, not a whole number of frames, or shorter
            than one sampling interval or step; the error suggests the least valid delta.
    """
    n = len(reference)
    if not (np.isfinite(delta) and delta > 0):
        msg = f"The RPE delta must be positive, got {delta!r}."
        raise MetricError(msg, option="rpe_delta")
    if unit is RPEUnit.FRAMES:
        if delta != int(delta):
            msg = f"An RPE delta in frames must be a whole number, got {delta!r}."
            raise MetricError(msg, option="rpe_delta")
        step = int(delta)
        starts = np.arange(0, n - step, 1 if all_pairs else step)
        return starts, starts + step
    if unit is RPEUnit.METRES:
        axis = reference.distances_m()
        steps = np.diff(axis)
        moving = steps[steps > 0]
        _check_delta_resolution(
            delta, float(np.median(moving)) if moving.size else 0.0, unit, "step length"
        )
        reach = np.searchsorted(axis, axis + delta, side="left")
    else:
        axis_ns = reference.stamps_ns
        interval_s = float(np.median(np.diff(axis_ns))) / _NS_PER_S if n > 1 else 0.0
        _check_delta_resolution(delta, interval_s, unit, "sampling interval")
        reach = np.searchsorted(axis_ns, axis_ns + round(delta * _NS_PER_S), side="left")
    # A pair ends at least one pose after it starts: at most N - 1 pairs, and the chain of
    # segments below advances on every turn.
    reach = np.maximum(reach, np.arange(1, n + 1))
    if all_pairs:
        starts = np.flatnonzero(reach < n)
        return starts, reach[starts]
    # Consecutive segments: follow the chain 0 -> reach[0] -> ...; the loop runs once per
    # segment (the path length over delta), not once per pose.
    firsts: list[int] = []
    i = 0
    reach_list = reach.tolist()
    while i < n and reach_list[i] < n:
        firsts.append(i)
        i = reach_list[i]
    starts = np.asarray(firsts, dtype=np.intp)
    return starts, reach[starts]


def _check_delta_resolution(delta: float, resolution: float, unit: RPEUnit, what: str) -> None:
    """Refuse an RPE delta below the reference's median sampling interval or step length."""
    least = max(resolution, _MIN_RPE_DELTA[unit])
    if delta >= least * (1.0 - 1e-3):  # a thousandth of slack: the suggestion passes
        return
    suggest = _round_up(least)
    msg = (
        f"An RPE delta of {delta:g} {unit.value} is below the reference's median {what} "
        f"({least:.3g} {unit.value}), so its pairs would not span a step; give at least "
        f"{suggest} {unit.value}, or count the delta in frames."
    )
    raise MetricError(msg, option="rpe_delta", suggest=suggest)


def _round_up(value: float) -> str:
    """Return ``value`` rounded up to two significant digits, as text (``0.011``).

    Values a thousandth above a round number (a median of 10000000.5 ns) round to it.
    """
    exponent = int(np.floor(np.log10(value))) - 1
    scale = 10.0**exponent
    return f"{np.ceil(value / scale - 1e-2) * scale:.2g}"


def compute_rpe(
    reference: Trajectory,
    aligned: Trajectory,
    *,
    delta: float = 1,
    unit: RPEUnit = RPEUnit.FRAMES,
    all_pairs: bool = False,
    pairs: tuple[IntArray, IntArray] | None = None,
) -> tuple[ErrorSeries, ErrorSeries | None]:
    """Relative pose error between pose ``i`` and the pose ``delta`` later.

    With orientations: ``E_ij = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``; its translation norm and
    rotation angle. Position-only: the norm of the difference of the displacement vectors
    ``(p_j - p_i) - (q_j - q_i)`` in the reference frame (no rotation error).

    Args:
        reference: matched reference poses Q.
        aligned: matched, aligned estimate poses P.
        delta: the step, in ``unit``.
        unit: frames, metres travelled on the reference, or seconds.
        all_pairs: every pose starts a pair (see :func:`rpe_pairs`).
        pairs: the ``(i, j)`` index pairs, when the caller has them from :func:`rpe_pairs`.

    Returns:
        Translation errors (m) and rotation errors (deg, None for position-only sources),
        stamped with each pair's first pose.

    Raises:
        MetricError: the delta yields no pair.
    """
    _require_matched(reference, aligned)
    i, j = pairs or rpe_pairs(reference, delta=delta, unit=unit, all_pairs=all_pairs)
    if i.size == 0:
        msg = (
            f"The RPE delta {delta:g} {unit.value} is longer than the matched trajectory "
            f"({len(reference)} poses, {reference.length_m:.2f} m, "
            f"{reference.span_words}); choose a smaller RPE delta."
        )
        raise MetricError(msg, option="rpe_delta")
    stamps = reference.stamps_ns[i]
    q_pos, p_pos = reference.positions_xyz, aligned.positions_xyz
    if reference.quat_xyzw is None or aligned.quat_xyzw is None:
        diff = (p_pos[j] - p_pos[i]) - (q_pos[j] - q_pos[i])
        return ErrorSeries(row_norms(diff), stamps, "m"), None
    rq = Rotation.from_quat(reference.quat_xyzw)
    rp = Rotation.from_quat(aligned.quat_xyzw)
    # E = dQ^-1 dP with dQ = Q_i^-1 Q_j, dP = P_i^-1 P_j. Its translation is
    # R(dQ)^T (t(dP) - t(dQ)), whose norm is |t(dP) - t(dQ)| (a rotation keeps lengths), and
    # its rotation R_qj^-1 (R_qi R_pi^-1) R_pj is conjugate to W_i W_j^-1 with W = R_q R_p^-1,
    # so it has the same angle: one composition over the poses, one over the pairs.
    dq_t = rq[i].apply(q_pos[j] - q_pos[i], inverse=True)
    dp_t = rp[i].apply(p_pos[j] - p_pos[i], inverse=True)
    err_t = row_norms(dp_t - dq_t)
    w = compose_quat(reference.quat_xyzw, conjugate_quat(aligned.quat_xyzw))
    err_r = relative_angle_deg(w[j], w[i])
    return ErrorSeries(err_t, stamps, "m"), ErrorSeries(err_r, stamps, "deg")


def drift_segment_lengths_m(length_m: float) -> tuple[float, ...]:
    """Segment lengths for drift: KITTI's 100..800 m, or 10 %..80 % of a path under 1 km."""
    if length_m >= 1000.0:
        return tuple(float(x) for x in range(100, 801, 100))
    return tuple(length_m * f for f in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8))


def compute_drift(
    reference: Trajectory,
    aligned: Trajectory,
    *,
    lengths_m: Sequence[float] | None = None,
    max_starts: int = 1000,
) -> ErrorSeries | None:
    """Translation drift in percent of the distance travelled, KITTI style.

    For segments of each length starting at (at most ``max_starts``, evenly spaced) poses,
    the relative-pose translation error over the segment divided by the distance the
    reference travelled over it (KITTI divides by the nominal length, which overstates
    drift when poses are sparse).

    Args:
        reference: matched reference poses.
        aligned: matched, aligned estimate poses.
        lengths_m: segment lengths; by default :func:`drift_segment_lengths_m`.
        max_starts: cap on segment start poses (statistics need no more).

    Returns:
        Drift per segment in percent, or None when the path is too short for any segment
        (a stationary recording).
    """
    _require_matched(reference, aligned)
    distances = reference.distances_m()
    total = float(distances[-1])
    if total <= 0.0:
        return None
    lengths = tuple(lengths_m) if lengths_m is not None else drift_segment_lengths_m(total)
    n = len(reference)
    step = max(1, n // max_starts)
    starts = np.arange(0, n, step)
    all_i: list[IntArray] = []
    all_j: list[IntArray] = []
    for length in lengths:  # a handful of lengths, each vectorized over the starts
        j = np.searchsorted(distances, distances[starts] + length, side="left")
        ok = j < n
        all_i.append(starts[ok])
        all_j.append(j[ok])
    i_idx = np.concatenate(all_i)
    if i_idx.size == 0:
        return None
    j_idx = np.concatenate(all_j)
    # Divide by the distance actually travelled from i to j (>= the nominal length).
    seg_len = distances[j_idx] - distances[i_idx]
    q_pos, p_pos = reference.positions_xyz, aligned.positions_xyz
    dq_t = q_pos[j_idx] - q_pos[i_idx]
    dp_t = p_pos[j_idx] - p_pos[i_idx]
    if reference.quat_xyzw is not None and aligned.quat_xyzw is not None:
        # The relative pose's translation error, as in compute_rpe (norm kept by rotation).
        dq_body = Rotation.from_quat(reference.quat_xyzw[i_idx]).apply(dq_t, inverse=True)
        dp_body = Rotation.from_quat(aligned.quat_xyzw[i_idx]).apply(dp_t, inverse=True)
        err = row_norms(dp_body - dq_body)
    else:
        err = row_norms(dp_t - dq_t)
    order = np.argsort(reference.stamps_ns[i_idx], kind="stable")
    return ErrorSeries((100.0 * err / seg_len)[order], reference.stamps_ns[i_idx][order], "%")


def share_within(errors: ErrorSeries, thresholds: Sequence[float]) -> dict[float, float]:
    """Fraction of errors ≤ each threshold (the reference-system paper's "96.3 % ≤ 15 cm")."""
    values = np.sort(errors.values)
    counts = np.searchsorted(values, np.asarray(thresholds, dtype=np.float64), side="right")
    return {float(t): float(c) / values.size for t, c in zip(thresholds, counts, strict=True)}


WORST_SEPARATION_S: Final = 2.0
"""Listed greatest errors lie at least this far apart in time: a burst is listed once."""
_PEAK_BLOCK: Final = 1024  # block maxima make each pick O(N / block + block + window)


def greatest_errors(
    errors: ErrorSeries,
    reference: Trajectory,
    *,
    count: int = 10,
    t0_ns: int | None = None,
    separation_s: float = WORST_SEPARATION_S,
) -> tuple[WorstPose, ...]:
    """The ``count`` greatest errors, largest first, with time and reference position.

    Large errors come in bursts of neighbouring poses (a system that loses track is off for
    a while), so the list names distinct places: each listed error is the greatest within
    ``separation_s`` either side of itself (a peak, not the flank of a greater one) and lies
    at least that far from every greater listed one (greedy non-maximum suppression in
    time). Every output numbers these the same way, ``#1`` ... ``#N`` by rank.

    Args:
        errors: per matched pose.
        reference: the matched reference poses (positions for each error).
        count: how many at most (fewer when the recording is short).
        t0_ns: the stamp ``t_s`` counts from; the first matched pose by default (the
            evaluation passes the whole reference's first pose, one clock for everything).
        separation_s: the least time between two listed errors, seconds (0: every pose).
    """
    n = len(errors)
    if min(count, n) == 0:
        return ()
    stamps = errors.stamps_ns
    reach_ns = round(separation_s * _NS_PER_S)
    blocks_n = -(-n // _PEAK_BLOCK)
    remaining = np.full(blocks_n * _PEAK_BLOCK, -np.inf)
    remaining[:n] = errors.values
    blocks = remaining.reshape(blocks_n, _PEAK_BLOCK)  # a view: masking updates it
    block_max = blocks.max(axis=1)
    picked: list[int] = []
    values = errors.values
    while len(picked) < min(count, n):  # one pass per listed error or skipped flank
        b = int(np.argmax(block_max))
        if block_max[b] == -np.inf:
            break
        i = b * _PEAK_BLOCK + int(np.argmax(blocks[b]))
        if reach_ns <= 0:
            lo, hi = i, i + 1
        else:  # poses closer than the separation (strictly) belong to this one's burst
            lo = int(np.searchsorted(stamps, stamps[i] - reach_ns, side="right"))
            hi = int(np.searchsorted(stamps, stamps[i] + reach_ns, side="left"))
        # listed only when it is the greatest within the separation either side: a pose on
        # the flank of a listed burst (2 s from its peak, greater than the rest) is not
        if values[i] >= values[lo:hi].max():
            picked.append(i)
        remaining[lo:hi] = -np.inf  # each pass masks its window: at most N / window passes
        first, last = lo // _PEAK_BLOCK, (hi - 1) // _PEAK_BLOCK
        block_max[first : last + 1] = blocks[first : last + 1].max(axis=1)
    t0 = int(reference.stamps_ns[0]) if t0_ns is None else int(t0_ns)
    return tuple(
        WorstPose(
            stamp_ns=int(stamps[i]),
            t_s=(int(stamps[i]) - t0) / _NS_PER_S,
            error=float(errors.values[i]),
            position_xyz=(
                float(reference.positions_xyz[i, 0]),
                float(reference.positions_xyz[i, 1]),
                float(reference.positions_xyz[i, 2]),
            ),
            index=int(i),
        )
        for i in picked
    )


def _require_matched(reference: Trajectory, estimate: Trajectory) -> None:
    if len(reference) != len(estimate):
        msg = f"Metrics need matched poses, got {len(reference)} and {len(estimate)}."
        raise MetricError(msg)
