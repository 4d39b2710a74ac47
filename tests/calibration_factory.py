"""Synthetic recordings with a known time offset and device offset, for the calibration tests.

A tracked body moves in the reference's world; the sensor sits on it at a known offset
``X`` (body -> sensor). The reference records the body at 120 Hz and loses tracking for a
few stretches; the estimate records the sensor at 30 Hz in its own drifting world frame,
with noise, on a clock that differs by a known offset (the stamp ``s`` of an estimate pose
happened at ``s + time_offset_s`` on the reference's clock).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.core.geometry import SimilarityTransform
from loceval.trajectory import Trajectory

T0_NS = 1_700_000_000 * 10**9
TRUE_DEVICE = SimilarityTransform(
    Rotation.from_euler("xyz", [12.0, -7.0, 95.0], degrees=True).as_matrix(),
    np.array([0.062, -0.035, 0.081]),
)
"""A camera 10 cm from the rigid body's origin, turned about all axes."""


class Motion(StrEnum):
    """What the body does."""

    HANDHELD = "handheld"  # +/- 30 deg about every axis, never repeating
    GROUND = "ground"  # a robot on the floor: rotation about z only
    LOOP = "loop"  # a robot driving the same 60 s loop over and over


@dataclass(frozen=True)
class Recording:
    """A generated reference/estimate pair and the truth behind it."""

    reference: Trajectory
    estimate: Trajectory
    time_offset_s: float
    device: SimilarityTransform
    scale: float


def _sines(
    rng: np.random.Generator, t: np.ndarray, *, k: int, f_lo: float, f_hi: float
) -> np.ndarray:
    """Sum of ``k`` unit-total-amplitude sines with random incommensurate frequencies."""
    freq = rng.uniform(f_lo, f_hi, k)
    amp = rng.uniform(0.5, 1.0, k)
    amp /= amp.sum()
    phase = rng.uniform(0, 2 * np.pi, k)
    return (amp * np.sin(2 * np.pi * freq * t[:, None] + phase)).sum(axis=1)


def _body(rng: np.random.Generator, t: np.ndarray, motion: Motion) -> tuple[np.ndarray, Rotation]:
    if motion is Motion.HANDHELD:
        xyz = np.stack([_sines(rng, t, k=4, f_lo=0.05, f_hi=0.35) for _ in range(3)], axis=1)
        xyz *= np.array([1.2, 1.0, 0.4])
        angles = np.stack([_sines(rng, t, k=3, f_lo=0.1, f_hi=0.6) for _ in range(3)], axis=1)
        return xyz + np.array([0.0, 0.0, 1.3]), Rotation.from_euler(
            "ZYX", 30.0 * angles, degrees=True
        )
    if motion is Motion.GROUND:
        xyz = np.stack([_sines(rng, t, k=6, f_lo=0.03, f_hi=0.2) for _ in range(2)], axis=1) * 3.0
        yaw = 120.0 * _sines(rng, t, k=6, f_lo=0.03, f_hi=0.5)
        xyz = np.column_stack([xyz, np.full(t.shape, 0.3)])
        return xyz, Rotation.from_euler("z", yaw[:, None], degrees=True)
    w = 2 * np.pi * t / 60.0
    xyz = np.stack(
        [4 * np.cos(w) + np.cos(2 * w + 0.4), 2.5 * np.sin(w) + 0.6 * np.sin(3 * w), 0.3 + 0 * w], 1
    )
    vel = np.stack(
        [-4 * np.sin(w) - 2 * np.sin(2 * w + 0.4), 2.5 * np.cos(w) + 1.8 * np.cos(3 * w)], 1
    )
    return xyz, Rotation.from_euler("z", np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))[:, None])


def make_recording(
    rng: np.random.Generator,
    *,
    motion: Motion = Motion.HANDHELD,
    duration_s: float = 120.0,
    reference_rate_hz: float = 120.0,
    estimate_rate_hz: float = 30.0,
    time_offset_s: float = -0.045,
    device: SimilarityTransform = TRUE_DEVICE,
    drift_m_per_min: float = 0.01,
    yaw_drift_deg_per_min: float = 0.1,
    orientation_noise_deg: float = 0.3,
    position_noise_m: float = 0.001,
    tracking_losses: int = 3,
    scale: float = 1.0,
    estimate_orientation: bool = True,
) -> Recording:
    """Generate one recording (``time_offset_s`` < 0: the estimate's stamps are late).

    The orientation noise is per axis (so the noise angle's RMS is sqrt(3) times it); the
    drift is a translation growing at ``drift_m_per_min`` in a random direction plus
    ``yaw_drift_deg_per_min`` of yaw; tracking losses last 0.5 to 2 s each.
    """
    seed = int(rng.integers(2**32))
    motion_rng = np.random.default_rng(seed)
    t_ref = np.arange(0.0, duration_s, 1.0 / reference_rate_hz)
    keep = np.ones(t_ref.shape, dtype=bool)
    for start in rng.uniform(5.0, duration_s - 5.0, tracking_losses):
        keep &= ~((t_ref > start) & (t_ref < start + rng.uniform(0.5, 2.0)))
    t_ref = t_ref[keep]
    p_body, r_body = _body(np.random.default_rng(seed), t_ref, motion)
    reference = Trajectory(
        T0_NS + np.rint(t_ref * 1e9).astype(np.int64),
        p_body,
        r_body.as_quat(),
        name="reference",
        source="synthetic",
        frame_id="world",
    )
    t_est = np.arange(0.5, duration_s - 0.5, 1.0 / estimate_rate_hz)
    t_est = t_est + motion_rng.uniform(-1e-3, 1e-3, t_est.shape)  # capture jitter
    p_b, r_b = _body(np.random.default_rng(seed), t_est, motion)
    r_sensor = r_b * Rotation.from_matrix(np.array(device.rotation))
    p_sensor = p_b + r_b.apply(np.array(device.translation))
    # The estimate's world: a fixed frame change, then drift that grows with time.
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    drift_t = np.outer(t_est / 60.0 * drift_m_per_min, direction)
    drift_r = Rotation.from_euler("z", yaw_drift_deg_per_min * t_est[:, None] / 60.0, degrees=True)
    world = Rotation.from_euler("xyz", rng.uniform(-180, 180, 3), degrees=True)
    world_t = rng.uniform(-5, 5, 3)
    p_est = world.apply(drift_r.apply(p_sensor) + drift_t) + world_t
    r_est = world * drift_r * r_sensor
    p_est = scale * p_est + rng.normal(0.0, position_noise_m, p_est.shape)
    noise = Rotation.from_rotvec(
        np.radians(rng.normal(0.0, orientation_noise_deg, (t_est.size, 3)))
    )
    q_est = (r_est * noise).as_quat() if estimate_orientation else None
    stamps = T0_NS + np.rint((t_est - time_offset_s) * 1e9).astype(np.int64)
    estimate = Trajectory(
        stamps, p_est, q_est, name="estimate", source="synthetic", frame_id="odom"
    )
    return Recording(reference, estimate, time_offset_s, device, scale)
