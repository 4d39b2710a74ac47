"""The clock's model along a run, and what the drift's estimate says about it.

:class:`ClockModel` is the time offset along the run, ``o(s) = o_0 + beta (s - s_0) + steps``
(see :mod:`loceval.calibration.drift`), which the evaluation applies to the estimate's stamps;
:class:`ClockDrift` holds the rate, the offset at the first pose and the steps the windows give,
with their sigmas, and :class:`DriftWindows` the windows themselves (for the report's plot).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from loceval.calibration.common import NS_PER_S
from loceval.core.arrays import BoolArray, FloatArray, IntArray
from loceval.trajectory import Trajectory

__all__ = [
    "MAX_RATE_PPM",
    "SIGNIFICANT_Z",
    "ClockDrift",
    "ClockModel",
    "ClockStep",
    "DriftWindows",
    "rate_of_slope",
    "slope_of_rate",
]

MAX_RATE_PPM = 1_000.0
"""The fastest drift searched and accepted, ppm (0.1 %: no crystal, a mistaken clock)."""
SIGNIFICANT_Z = 3.0
"""A rate (or a step) counts when it exceeds this many sigma."""


@dataclass(frozen=True, slots=True)
class ClockStep:
    """A jump of the estimate's clock.

    Attributes:
        stamp_ns: the estimate's first stamp after the jump (its own clock).
        at_s: when it happened, seconds on the reference's clock after the reference's first
            pose (the result's time base).
        sigma_at_s: 1-sigma of ``at_s``.
        size_s: the change of the time offset there (negative: the clock jumped ahead).
        sigma_size_s: 1-sigma of ``size_s``.
    """

    stamp_ns: int
    at_s: float
    sigma_at_s: float
    size_s: float
    sigma_size_s: float

    def to_dict(self) -> dict[str, float]:
        """Return the contract's step object."""
        return {
            "at_s": self.at_s,
            "sigma_at_s": self.sigma_at_s,
            "size_s": self.size_s,
            "sigma_size_s": self.sigma_size_s,
        }


def slope_of_rate(rate_ppm: float) -> float:
    """The offset's slope (s per s of the estimate's clock) of a clock ``rate_ppm`` fast."""
    r = rate_ppm * 1e-6
    return -r / (1.0 + r)


def rate_of_slope(slope: float) -> float:
    """The clock's rate in ppm whose offset has ``slope`` (inverse of :func:`slope_of_rate`)."""
    return -slope / (1.0 + slope) * 1e6


@dataclass(frozen=True, slots=True)
class ClockModel:
    """The time offset along the run: ``o(s) = offset_s + slope (s - epoch) + steps``.

    Attributes:
        offset_s: the offset at ``epoch_ns``, seconds.
        epoch_ns: the estimate's first stamp (its clock).
        rate_ppm: how fast the estimate's clock runs against the reference's.
        steps: ``(stamp_ns, size_s)``: from that stamp of the estimate on, the offset
            changes by ``size_s``.
    """

    offset_s: float
    epoch_ns: int
    rate_ppm: float = 0.0
    steps: tuple[tuple[int, float], ...] = ()

    @property
    def varies(self) -> bool:
        """Whether the offset changes along the run."""
        return self.rate_ppm != 0.0 or bool(self.steps)

    def offsets_s(self, stamps_ns: IntArray) -> FloatArray:
        """Return (N,) the offsets to add to ``stamps_ns`` (the estimate's clock), seconds."""
        return self.offset_s + self.varying_s(stamps_ns)

    def varying_s(self, stamps_ns: IntArray) -> FloatArray:
        """Return (N,) the offsets less the one at the epoch, seconds."""
        since = (np.asarray(stamps_ns, dtype=np.int64) - np.int64(self.epoch_ns)).astype(
            np.float64
        ) / NS_PER_S
        out: FloatArray = slope_of_rate(self.rate_ppm) * since
        for stamp, size in self.steps:  # a loop over the few steps, not over poses
            out = out + size * (np.asarray(stamps_ns) >= stamp)
        return out

    def restamped(self, trajectory: Trajectory) -> Trajectory:
        """Return ``trajectory`` with the varying part of the offset added to its stamps.

        The constant part (``offset_s``) stays for the association to add, so the result's
        ``time_offset_s`` keeps its meaning (the offset at the estimate's first pose). Poses
        that a step would put at or before their predecessor (a clock set back, whose
        stamps interleave) are dropped.
        """
        if not self.varies:
            return trajectory
        # In int64: float64 holds an epoch stamp only to a quarter of a microsecond.
        moved_ns = np.rint(self.varying_s(trajectory.stamps_ns) * NS_PER_S).astype(np.int64)
        stamps = trajectory.stamps_ns + moved_ns
        keep = np.concatenate(([True], stamps[1:] > np.maximum.accumulate(stamps)[:-1]))
        if keep.all():
            return replace(trajectory, stamps_ns=stamps)
        kept = trajectory.select(np.flatnonzero(keep))
        return replace(kept, stamps_ns=stamps[keep])


@dataclass(frozen=True, slots=True, eq=False)
class DriftWindows:
    """The windows' offsets, for the report's plot.

    Attributes:
        centre_s: (W,) each window's centre, seconds of the estimate's clock after its first
            stamp.
        offset_s: (W,) the offset found in each (NaN: no offset, too little motion).
        sigma_s: (W,) its 1-sigma (NaN likewise).
        used: (W,) whether the model used it at full weight (False: an outlier, or none).
    """

    centre_s: FloatArray
    offset_s: FloatArray
    sigma_s: FloatArray
    used: BoolArray

    def __post_init__(self) -> None:
        """Make the arrays read-only copies."""
        for name in ("centre_s", "offset_s", "sigma_s", "used"):
            arr = np.array(getattr(self, name))
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)


@dataclass(frozen=True, slots=True, eq=False)
class ClockDrift:
    """What the data say about the estimate's clock along the run.

    Attributes:
        rate_ppm: how fast the estimate's clock runs against the reference's (negative:
            slow), parts per million.
        sigma_rate_ppm: its 1-sigma.
        offset_s: the time offset at the estimate's first pose under this model, seconds.
        sigma_offset_s: its 1-sigma.
        epoch_ns: the estimate's first stamp.
        duration_s: the span of the estimate's clock the windows cover, seconds.
        steps: the steps found (significant ones only).
        windows: the windows' offsets.
        scatter: the windows' scatter about the model, in their own sigmas (about 1).
    """

    rate_ppm: float
    sigma_rate_ppm: float
    offset_s: float
    sigma_offset_s: float
    epoch_ns: int
    duration_s: float
    steps: tuple[ClockStep, ...]
    windows: DriftWindows = field(repr=False)
    scatter: float

    @property
    def significant(self) -> bool:
        """Whether the rate differs from 0 by more than :data:`SIGNIFICANT_Z` sigma."""
        return abs(self.rate_ppm) > SIGNIFICANT_Z * self.sigma_rate_ppm

    @property
    def moved_s(self) -> float:
        """How far the offset moves over the run by the rate alone, seconds."""
        return abs(slope_of_rate(self.rate_ppm)) * self.duration_s

    def model(self, *, with_rate: bool, with_steps: bool, offset_s: float) -> ClockModel:
        """The model to apply: the rate and steps asked for, from ``offset_s`` at the epoch."""
        return ClockModel(
            offset_s=offset_s,
            epoch_ns=self.epoch_ns,
            rate_ppm=self.rate_ppm if with_rate else 0.0,
            steps=tuple((s.stamp_ns, s.size_s) for s in self.steps) if with_steps else (),
        )
