"""Ranging evaluation: how accurate are a radio system's distance measurements themselves?

The reference-robot paper (§V) evaluates the nanoPAN ranges against the distances from the
reference positions to the anchors before it evaluates any positioning algorithm; this
module does that for any ranging system (UWB, BLE, nanoPAN).

For every range measurement the reference is interpolated at the measurement's own stamp
(linear position, SLERP orientation, never across a reference interval longer than
``max_gap_ns``: :func:`loceval.registration.association.associate`), the tag position is the
reference
pose applied to ``tag_offset_xyz`` (body frame), and

    error = measured range - |tag position - anchor position|

so non-line-of-sight errors (a longer, reflected path) are positive. Per anchor and over
all measurements the module gives n, bias (mean error), std (population, ``ddof=0``),
RMSE, MAE, max |error|, the share of outliers (``|error| > outlier_threshold_m``), bias,
std and RMSE over the inliers, and a least-squares line per anchor
``range = offset + scale · true distance`` (ordinary least squares over all its
measurements) that a team can use to calibrate. Everything is computed with
:func:`numpy.bincount` over the anchor index: no loop over measurements.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Final

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.core.arrays import FloatArray, IntArray
from loceval.core.quantities import format_duration
from loceval.errors import AssociationError, InputError
from loceval.metrics.pose_errors import ErrorSeries
from loceval.readers.radio import Ranges
from loceval.registration.association import DEFAULT_MAX_GAP_NS, AssociationMethod, associate
from loceval.trajectory import Trajectory

__all__ = [
    "DEFAULT_DISTANCE_BIN_M",
    "DEFAULT_OUTLIER_THRESHOLD_M",
    "MAX_DISTANCE_BINS",
    "AnchorRanging",
    "DistanceBin",
    "RangeFit",
    "RangeStats",
    "RangingResult",
    "evaluate_ranging",
    "tag_positions",
]

DEFAULT_OUTLIER_THRESHOLD_M: Final = 1.0
"""|error| beyond this is an outlier (a non-line-of-sight or multipath measurement)."""
DEFAULT_DISTANCE_BIN_M: Final = 2.0
"""Width of the true-distance bins of the error-versus-distance table."""
MAX_DISTANCE_BINS: Final = 1000
"""Most true-distance bins: a table, not one row per measurement."""

_NS_PER_S: Final = 1_000_000_000
_MIN_FIT_SPREAD_M: Final = 1e-3
"""A fit needs true distances spread by more than this (standard deviation), else None."""


@dataclass(frozen=True, slots=True)
class RangeStats:
    """Statistics of ranging errors (measured minus true), metres.

    The inlier figures are None when every measurement is an outlier.
    """

    n: int
    bias_m: float
    std_m: float
    rmse_m: float
    mae_m: float
    max_abs_m: float
    outlier_share: float
    inlier_n: int
    inlier_bias_m: float | None
    inlier_std_m: float | None
    inlier_rmse_m: float | None

    def to_dict(self) -> dict[str, object]:
        """Return the contract's ``overall`` object (without the inlier figures)."""
        return {
            "n": self.n,
            "bias_m": self.bias_m,
            "std_m": self.std_m,
            "rmse_m": self.rmse_m,
            "mae_m": self.mae_m,
            "max_abs_m": self.max_abs_m,
            "outlier_share": self.outlier_share,
        }

    def inliers_dict(self) -> dict[str, float | None]:
        """Return the contract's ``inliers`` object."""
        return {
            "bias_m": self.inlier_bias_m,
            "std_m": self.inlier_std_m,
            "rmse_m": self.inlier_rmse_m,
        }


@dataclass(frozen=True, slots=True)
class RangeFit:
    """Least-squares line ``range = offset_m + scale · true distance`` of one anchor."""

    offset_m: float
    scale: float


@dataclass(frozen=True, slots=True)
class AnchorRanging:
    """The ranging figures of one anchor.

    Attributes:
        id: the anchor's id.
        position_xyz: the anchor's position, metres.
        stats: the error statistics of its evaluated measurements.
        fit: the calibration line, or None (fewer than two measurements, or true
            distances that hardly vary).
    """

    id: str
    position_xyz: tuple[float, float, float]
    stats: RangeStats
    fit: RangeFit | None

    def to_dict(self) -> dict[str, object]:
        """Return the contract's per-anchor object."""
        return {
            "id": self.id,
            "position": list(self.position_xyz),
            **self.stats.to_dict(),
            "inliers": self.stats.inliers_dict(),
            "fit": None
            if self.fit is None
            else {"offset_m": self.fit.offset_m, "scale": self.fit.scale},
        }


@dataclass(frozen=True, slots=True)
class DistanceBin:
    """Ranging errors of the measurements whose true distance lies in ``[start_m, end_m)``."""

    start_m: float
    end_m: float
    n: int
    bias_m: float
    std_m: float
    rmse_m: float


@dataclass(frozen=True, slots=True, eq=False)
class RangingResult:
    """The ranging evaluation of one recording.

    Attributes:
        outlier_threshold_m: the |error| beyond which a measurement is an outlier.
        anchors: the figures of every anchor with at least one evaluated measurement,
            in the anchors file's order.
        overall: the figures over all evaluated measurements.
        unused_anchors: ids of anchors with no evaluated measurement.
        distance_bins: error against true distance, non-empty bins in order.
        errors: (M,) error of every evaluated measurement with its stamp (error over time).
        anchor_index: (M,) anchor of every evaluated measurement.
        true_distance_m: (M,) the true distance of every evaluated measurement.
        measured_m: (M,) the measured range of every evaluated measurement.
        dropped_outside: measurements before or after the reference's time span.
        dropped_gap: measurements inside a reference gap (tracking loss).
        warnings: what the user should know (drops, reader notes).
    """

    outlier_threshold_m: float
    anchors: tuple[AnchorRanging, ...]
    overall: RangeStats
    unused_anchors: tuple[str, ...]
    distance_bins: tuple[DistanceBin, ...]
    errors: ErrorSeries
    anchor_index: IntArray
    true_distance_m: FloatArray
    measured_m: FloatArray
    dropped_outside: int
    dropped_gap: int
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        """Make read-only copies of the per-measurement arrays."""
        for name in ("anchor_index", "true_distance_m", "measured_m"):
            array = np.array(getattr(self, name), copy=True)
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        object.__setattr__(self, "warnings", tuple(self.warnings))

    def to_dict(self) -> dict[str, object]:
        """Return the ``ranging`` object of the JSON contract."""
        return {
            "outlier_threshold_m": self.outlier_threshold_m,
            "anchors": [a.to_dict() for a in self.anchors],
            "overall": self.overall.to_dict(),
            "unused_anchors": list(self.unused_anchors),
        }

    def document(self, options: Mapping[str, object]) -> dict[str, object]:
        """Return the result document's ``ranging`` object.

        The contract's object, then the ranging ``options`` it ran with, the dropped ranges
        and the warnings.
        """
        return {
            **self.to_dict(),
            "options": dict(options),
            "dropped": {"outside": self.dropped_outside, "gap": self.dropped_gap},
            "warnings": list(self.warnings),
        }


def tag_positions(
    reference: Trajectory, tag_offset_xyz: tuple[float, float, float] | None
) -> FloatArray:
    """Return the (N, 3) tag positions: each reference pose applied to the body-frame offset.

    Args:
        reference: the poses of the tag's carrier.
        tag_offset_xyz: the tag in the carrier's body frame, metres; None or zero for none.

    Returns:
        (N, 3) positions in the reference's frame, metres.

    Raises:
        InputError: an offset other than zero is given but the reference has no orientation,
            or the offset is not three finite numbers.
    """
    if tag_offset_xyz is None:
        return reference.positions_xyz
    offset = np.asarray(tag_offset_xyz, dtype=np.float64)
    if offset.shape != (3,) or not np.isfinite(offset).all():
        msg = f"The tag offset must be three finite metres x y z, got {tag_offset_xyz!r}."
        raise InputError(msg, option="tag_offset_xyz")
    if not offset.any():
        return reference.positions_xyz
    if reference.quat_xyzw is None:
        msg = (
            f"The reference {reference.name!r} has no orientations, so the tag offset "
            f"{tuple(float(v) for v in offset)!r} cannot be turned into the building frame; "
            "use a reference with orientations or drop the offset."
        )
        raise InputError(msg, option="tag_offset_xyz")
    out: FloatArray = reference.positions_xyz + Rotation.from_quat(reference.quat_xyzw).apply(
        offset
    )
    return out


def evaluate_ranging(
    reference: Trajectory,
    ranges: Ranges,
    *,
    max_gap_ns: int = DEFAULT_MAX_GAP_NS,
    tag_offset_xyz: tuple[float, float, float] | None = None,
    outlier_threshold_m: float = DEFAULT_OUTLIER_THRESHOLD_M,
    distance_bin_m: float = DEFAULT_DISTANCE_BIN_M,
) -> RangingResult:
    """Compare every range with the true distance from the reference to its anchor.

    Args:
        reference: the ground truth of the tag's carrier (body frame origin).
        ranges: the measurements and their anchors.
        max_gap_ns: longest reference interval bridged by interpolation, nanoseconds;
            measurements inside a longer interval (tracking loss) are dropped and counted.
        tag_offset_xyz: the tag's position in the reference body frame, metres (needs a
            reference with orientations); None when the tag is at the tracked origin.
        outlier_threshold_m: |error| beyond which a measurement is an outlier.
        distance_bin_m: width of the error-versus-true-distance bins.

    Returns:
        The per-anchor and overall figures and the per-measurement errors.

    Raises:
        InputError: an option is out of range, a tag offset is given for a position-only
            reference, or there are no ranges.
        AssociationError: no measurement falls within the reference's coverage.
    """
    _check_options(outlier_threshold_m, distance_bin_m, max_gap_ns)
    tag_positions(reference, tag_offset_xyz)  # check the offset before the work
    if not len(ranges):
        msg = f"No range measurements in {ranges.source!r} to evaluate; check the file."
        raise InputError(msg)
    if tag_offset_xyz is None or not np.any(tag_offset_xyz):
        reference = reference.without_orientation()  # no SLERP needed without an offset
    # Anchors share stamps: interpolate once per distinct stamp.
    unique_ns, inverse = np.unique(ranges.stamps_ns, return_inverse=True)
    probe = Trajectory(unique_ns, np.zeros((unique_ns.shape[0], 3)), name="ranges")
    matched = associate(
        reference,
        probe,
        method=AssociationMethod.INTERPOLATE,
        max_gap_ns=max_gap_ns,
        min_matches=0,
    )
    found = np.zeros(unique_ns.shape[0], dtype=bool)
    found[matched.estimate_index] = True
    position_of = np.zeros((unique_ns.shape[0], 3))
    # The offset is applied to the interpolated poses (SLERP orientation), not interpolated.
    position_of[matched.estimate_index] = tag_positions(matched.reference, tag_offset_xyz)
    ok = found[inverse]
    t_ref = reference.stamps_ns
    outside_mask = (ranges.stamps_ns < t_ref[0]) | (ranges.stamps_ns > t_ref[-1])
    dropped_outside = int(outside_mask.sum())
    dropped_gap = int((~ok & ~outside_mask).sum())
    total = len(ranges)
    if not ok.any():
        msg = (
            f"None of the {total} ranges of {ranges.source!r} (covering "
            f"{_span(ranges.stamps_ns)}) falls within the reference {reference.name!r} "
            f"({_span(t_ref)}) outside its tracking loss; check that both record the same "
            "run in the same clock."
        )
        raise AssociationError(msg)
    index = ranges.anchor_index[ok]
    measured = ranges.range_m[ok]
    stamps = ranges.stamps_ns[ok]
    anchors_xyz = ranges.anchors.positions_xyz
    true = np.linalg.norm(position_of[inverse[ok]] - anchors_xyz[index], axis=1)
    error = measured - true
    k = len(ranges.anchors)
    per_anchor = _group_stats(error, index, k, outlier_threshold_m)
    overall = _group_stats(error, np.zeros(error.shape[0], dtype=np.intp), 1, outlier_threshold_m)
    fits = _fits(true, measured, index, k)
    anchors = tuple(
        AnchorRanging(
            id=ranges.anchors.ids[a],
            position_xyz=(
                float(anchors_xyz[a, 0]),
                float(anchors_xyz[a, 1]),
                float(anchors_xyz[a, 2]),
            ),
            stats=per_anchor[a],
            fit=fits[a],
        )
        for a in range(k)  # one per anchor, not per measurement
        if per_anchor[a].n
    )
    unused = tuple(ranges.anchors.ids[a] for a in range(k) if not per_anchor[a].n)
    distance_bins = _distance_bins(true, error, distance_bin_m)
    notes = list(ranges.warnings)
    if dropped_outside:
        notes.append(
            f"{dropped_outside} of {total} ranges lie outside the reference's time span and "
            "were not evaluated."
        )
    if dropped_gap:
        notes.append(
            f"{dropped_gap} of {total} ranges fall in reference gaps longer than "
            f"{format_duration(max_gap_ns / _NS_PER_S)} (tracking loss) and were not evaluated."
        )
    if unused:
        notes.append(f"{len(unused)} of {k} anchors have no evaluated range: {', '.join(unused)}.")
    return RangingResult(
        outlier_threshold_m=float(outlier_threshold_m),
        anchors=anchors,
        overall=overall[0],
        unused_anchors=unused,
        distance_bins=distance_bins,
        errors=ErrorSeries(error, stamps, "m"),
        anchor_index=index,
        true_distance_m=true,
        measured_m=measured,
        dropped_outside=dropped_outside,
        dropped_gap=dropped_gap,
        warnings=tuple(notes),
    )


def _distance_bins(
    true_m: FloatArray, error: FloatArray, width_m: float
) -> tuple[DistanceBin, ...]:
    """Return the error statistics per non-empty true-distance bin ``[k w, (k + 1) w)``."""
    bin_of = np.floor(true_m / width_m)
    if float(bin_of.max()) >= MAX_DISTANCE_BINS:
        msg = (
            f"The distance bin width {width_m!r} m cuts distances up to "
            f"{float(true_m.max()):.1f} m into more than {MAX_DISTANCE_BINS} bins; use a "
            f"width of at least {float(true_m.max()) / MAX_DISTANCE_BINS:.3g} m."
        )
        raise InputError(msg, option="distance_bin_m")
    used, compact = np.unique(bin_of.astype(np.intp), return_inverse=True)
    stats = _group_stats(error, compact, used.shape[0], math.inf)
    return tuple(
        DistanceBin(
            start_m=float(b) * width_m,
            end_m=float(b + 1) * width_m,
            n=st.n,
            bias_m=st.bias_m,
            std_m=st.std_m,
            rmse_m=st.rmse_m,
        )
        for b, st in zip(used.tolist(), stats, strict=True)  # one per bin
    )


def _group_stats(
    error: FloatArray, group: IntArray, n_groups: int, threshold_m: float
) -> list[RangeStats]:
    """Return the statistics of ``error`` per group 0..n_groups-1 (empty groups: n = 0)."""
    n = np.bincount(group, minlength=n_groups)
    safe_n = np.maximum(n, 1)
    mean = np.bincount(group, weights=error, minlength=n_groups) / safe_n
    # Two passes (deviations from each group's mean) keep the variance exact for large biases.
    dev = error - mean[group]
    var = np.bincount(group, weights=dev * dev, minlength=n_groups) / safe_n
    abs_error = np.abs(error)
    mse = np.bincount(group, weights=error * error, minlength=n_groups) / safe_n
    mae = np.bincount(group, weights=abs_error, minlength=n_groups) / safe_n
    max_abs = np.zeros(n_groups)
    order = np.argsort(group, kind="stable")
    present = np.flatnonzero(n)
    starts = np.concatenate(([0], np.cumsum(n)[:-1]))[present]
    max_abs[present] = np.maximum.reduceat(abs_error[order], starts)
    inlier = abs_error <= threshold_m
    gi = group[inlier]
    ei = error[inlier]
    n_in = np.bincount(gi, minlength=n_groups)
    safe_in = np.maximum(n_in, 1)
    mean_in = np.bincount(gi, weights=ei, minlength=n_groups) / safe_in
    dev_in = ei - mean_in[gi]
    var_in = np.bincount(gi, weights=dev_in * dev_in, minlength=n_groups) / safe_in
    mse_in = np.bincount(gi, weights=ei * ei, minlength=n_groups) / safe_in
    out = []
    for g in range(n_groups):  # one per anchor or bin, not per measurement
        has_in = bool(n_in[g])
        out.append(
            RangeStats(
                n=int(n[g]),
                bias_m=float(mean[g]),
                std_m=float(np.sqrt(var[g])),
                rmse_m=float(np.sqrt(mse[g])),
                mae_m=float(mae[g]),
                max_abs_m=float(max_abs[g]),
                outlier_share=float((n[g] - n_in[g]) / n[g]) if n[g] else 0.0,
                inlier_n=int(n_in[g]),
                inlier_bias_m=float(mean_in[g]) if has_in else None,
                inlier_std_m=float(np.sqrt(var_in[g])) if has_in else None,
                inlier_rmse_m=float(np.sqrt(mse_in[g])) if has_in else None,
            )
        )
    return out


def _fits(
    true_m: FloatArray, measured_m: FloatArray, group: IntArray, n_groups: int
) -> list[RangeFit | None]:
    """Least-squares ``measured = offset + scale · true`` per group (centred sums)."""
    n = np.bincount(group, minlength=n_groups)
    safe_n = np.maximum(n, 1)
    mean_d = np.bincount(group, weights=true_m, minlength=n_groups) / safe_n
    mean_r = np.bincount(group, weights=measured_m, minlength=n_groups) / safe_n
    dd = true_m - mean_d[group]
    dr = measured_m - mean_r[group]
    sxx = np.bincount(group, weights=dd * dd, minlength=n_groups)
    sxy = np.bincount(group, weights=dd * dr, minlength=n_groups)
    usable = (n >= 2) & (sxx > n * _MIN_FIT_SPREAD_M**2)
    scale = np.divide(sxy, sxx, out=np.zeros(n_groups), where=usable)
    offset = mean_r - scale * mean_d
    return [
        RangeFit(offset_m=float(offset[g]), scale=float(scale[g])) if usable[g] else None
        for g in range(n_groups)  # one per anchor
    ]


def _check_options(outlier_threshold_m: float, distance_bin_m: float, max_gap_ns: int) -> None:
    _check_positive(outlier_threshold_m, "outlier_threshold_m", "the outlier threshold")
    _check_positive(distance_bin_m, "distance_bin_m", "the distance bin width")
    if max_gap_ns <= 0:
        msg = f"The longest bridged reference gap must be positive, got {max_gap_ns!r} ns."
        raise InputError(msg, option="max_gap_s")


def _check_positive(value: float, option: str, words: str) -> None:
    if not (np.isfinite(value) and value > 0):
        msg = f"{words.capitalize()} must be a positive number of metres, got {value!r}."
        raise InputError(msg, option=option)


def _span(stamps_ns: IntArray) -> str:
    if stamps_ns.shape[0] == 0:
        return "nothing"
    return f"{stamps_ns[0] / 1e9:.3f} s to {stamps_ns[-1] / 1e9:.3f} s"
