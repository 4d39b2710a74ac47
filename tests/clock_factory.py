"""Synthetic recordings whose estimate runs on a drifting, stepping clock (known truth).

The recordings of :mod:`tests.calibration_factory` are made with the estimate's stamps on the
reference's clock, then stamped again by a clock model: the estimate's clock reads

``s(t) = t - offset_s + rate_ppm * 1e-6 * (t - t_first) + jump_s * [t >= t_step]``

at reference time ``t`` (``t_first``: the estimate's first pose). So at its first pose the
estimate's stamps are ``offset_s`` early (the time offset to add is ``offset_s``), a clock
``rate_ppm`` fast gains that many microseconds per second, and at ``t_step`` it jumps ahead by
``jump_s`` (an NTP step; negative: it is set back). The time offset to add to a stamp is then
``t - s``: it falls by ``rate / (1 + rate)`` per second of the estimate's clock and by
``jump_s`` at the step.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from loceval.trajectory import Trajectory
from tests.calibration_factory import T0_NS, Motion, Recording, make_recording

__all__ = ["ClockTruth", "DriftRecording", "make_drifting_recording", "restamp"]


@dataclass(frozen=True)
class ClockTruth:
    """The estimate's clock against the reference's (see the module's docstring).

    Attributes:
        offset_s: the time offset to add to the estimate's first stamp, seconds.
        rate_ppm: how fast the estimate's clock runs, parts per million (negative: slow).
        step_at_s: when its clock jumps, seconds after the reference's first pose (None: never).
        jump_s: by how much it jumps ahead then, seconds.
    """

    offset_s: float = 0.0
    rate_ppm: float = 0.0
    step_at_s: float | None = None
    jump_s: float = 0.0

    def offsets_s(self, t_s: np.ndarray, t_first_s: float) -> np.ndarray:
        """The offset ``t - s(t)`` at reference times ``t_s`` (seconds after T0)."""
        stepped = 0.0 if self.step_at_s is None else self.jump_s * (t_s >= self.step_at_s)
        return self.offset_s - self.rate_ppm * 1e-6 * (t_s - t_first_s) - stepped


@dataclass(frozen=True)
class DriftRecording:
    """A recording with its clock's truth and the estimate stamped on the reference's clock."""

    recording: Recording
    clock: ClockTruth
    true_clock_estimate: Trajectory
    """The same estimate poses stamped on the reference's clock (what a perfect clock gives)."""

    @property
    def reference(self) -> Trajectory:
        """The reference."""
        return self.recording.reference

    @property
    def estimate(self) -> Trajectory:
        """The estimate on its own (drifting) clock."""
        return self.recording.estimate


def restamp(estimate: Trajectory, clock: ClockTruth) -> Trajectory:
    """Stamp an estimate whose stamps are reference times with the drifting ``clock``.

    Raises:
        ValueError: a backward jump would interleave the stamps (not what this makes).
    """
    t_s = (estimate.stamps_ns - T0_NS).astype(np.float64) / 1e9
    offsets = clock.offsets_s(t_s, float(t_s[0]))
    stamps = estimate.stamps_ns - np.rint(offsets * 1e9).astype(np.int64)
    if not (np.diff(stamps) > 0).all():
        msg = "The clock's backward jump is longer than the interval between two poses."
        raise ValueError(msg)
    return dataclasses.replace(estimate, stamps_ns=stamps)


def make_drifting_recording(
    rng: np.random.Generator,
    clock: ClockTruth,
    *,
    motion: Motion = Motion.HANDHELD,
    duration_s: float = 600.0,
    reference_rate_hz: float = 100.0,
    estimate_rate_hz: float = 30.0,
    estimate_orientation: bool = True,
    tracking_losses: int = 3,
    position_noise_m: float = 0.001,
    **options: float,
) -> DriftRecording:
    """Generate a recording (:func:`tests.calibration_factory.make_recording`) on ``clock``.

    ``options`` go to ``make_recording`` (noise, drift of the estimate's frame).
    """
    rec = make_recording(
        rng,
        motion=motion,
        duration_s=duration_s,
        reference_rate_hz=reference_rate_hz,
        estimate_rate_hz=estimate_rate_hz,
        time_offset_s=0.0,
        estimate_orientation=estimate_orientation,
        tracking_losses=tracking_losses,
        position_noise_m=position_noise_m,
        **options,
    )
    drifting = restamp(rec.estimate, clock)
    return DriftRecording(
        recording=dataclasses.replace(rec, estimate=drifting, time_offset_s=clock.offset_s),
        clock=clock,
        true_clock_estimate=rec.estimate,
    )
