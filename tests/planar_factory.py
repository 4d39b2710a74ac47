"""Planar recordings of many kinds: a ground robot's loops, with known device offset.

A robot drives a closed path on the floor (rotation about z only) and the estimate follows
its sensor, mounted at a known offset. The families vary what the rotation about z of the
device offset is told by: the loop's shape (ellipse, racetrack, figure eight, a wobbly
random loop, a limacon), the speed profile (constant, sinusoidal, stop-and-go), whether the
robot drives forward (heading along the path) or also turns on its own (holonomic), the
noise, the estimate's heading and position drift, its rate, the run's length and the
mounting.

:data:`TUNING` and :data:`HELD_OUT` split the families: the honest sigma of
:mod:`loceval.calibration.handeye` was checked on the first only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.core.geometry import SimilarityTransform
from loceval.trajectory import Trajectory
from tests.calibration_factory import T0_NS, Recording

__all__ = ["HELD_OUT", "TUNING", "PlanarFamily", "make_planar_recording"]


@dataclass(frozen=True)
class PlanarFamily:
    """How a planar recording is made (see the module's docstring)."""

    shape: str = "ellipse"
    """``ellipse``, ``racetrack``, ``figure8``, ``limacon`` or ``wobbly``."""
    speed: str = "constant"
    """``constant``, ``sinusoidal`` or ``stop_and_go``."""
    size_m: float = 4.0
    speed_m_s: float = 0.6
    holonomic: bool = False
    """The robot also turns on its own (an omnidirectional base), not only along its path."""
    duration_s: float = 240.0
    reference_rate_hz: float = 120.0
    estimate_rate_hz: float = 30.0
    position_noise_m: float = 0.002
    orientation_noise_deg: float = 0.3
    yaw_drift_deg_per_min: float = 5.0
    drift_m_per_min: float = 0.02
    device_yaw_deg: float = 95.0
    device_tilt_deg: float = 0.0
    """Roll and pitch of the sensor on the robot (0: mounted level)."""
    drift_model: str = "odometry"
    """``odometry``: the estimate integrates its motion with a heading error that grows (at
    ``yaw_drift_deg_per_min``, plus a random walk), as wheel odometry or a VIO does;
    ``world``: its whole frame turns about its origin (a localisation whose map turns)."""


TUNING = (
    PlanarFamily(),
    PlanarFamily(shape="racetrack", speed="sinusoidal"),
    PlanarFamily(
        shape="ellipse", speed="sinusoidal", yaw_drift_deg_per_min=20.0, drift_model="world"
    ),
    PlanarFamily(shape="racetrack", device_tilt_deg=3.0, duration_s=120.0),
    PlanarFamily(shape="figure8", speed="stop_and_go", duration_s=300.0),
    PlanarFamily(shape="ellipse", holonomic=True, device_yaw_deg=10.0),
    PlanarFamily(
        shape="figure8",
        estimate_rate_hz=10.0,
        position_noise_m=0.01,
        orientation_noise_deg=1.0,
        duration_s=400.0,
    ),
    PlanarFamily(shape="racetrack", speed="stop_and_go", duration_s=60.0, size_m=2.0),
)
"""The families the travel axis's sigma was chosen on (with seeds 0 to 9 of each)."""

HELD_OUT = (
    PlanarFamily(shape="wobbly", speed="stop_and_go", duration_s=300.0),
    PlanarFamily(shape="wobbly", speed="sinusoidal", holonomic=True, duration_s=180.0),
    PlanarFamily(
        shape="limacon",
        speed="constant",
        estimate_rate_hz=15.0,
        position_noise_m=0.02,
        orientation_noise_deg=0.7,
        duration_s=600.0,
    ),
    PlanarFamily(
        shape="wobbly",
        speed="stop_and_go",
        size_m=8.0,
        speed_m_s=1.2,
        yaw_drift_deg_per_min=30.0,
        drift_m_per_min=0.1,
        duration_s=90.0,
        device_yaw_deg=-30.0,
        drift_model="world",
    ),
    PlanarFamily(
        shape="limacon",
        speed="sinusoidal",
        holonomic=True,
        size_m=2.0,
        speed_m_s=0.3,
        orientation_noise_deg=0.1,
        yaw_drift_deg_per_min=1.0,
        device_tilt_deg=2.0,
        duration_s=400.0,
        device_yaw_deg=180.0,
    ),
)
"""Families never used to choose the method: two shapes never tuned on (a wobbly random loop,
a limacon), and other speeds, noise, rates, lengths and mountings than the tuning's."""


def _curve(shape: str, u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 2) points of a closed curve of unit size at parameters ``u`` in [0, 2 pi)."""
    if shape == "ellipse":
        return np.stack([np.cos(u), 0.6 * np.sin(u)], axis=1)
    if shape == "racetrack":
        # A superellipse: long straights, tight ends.
        c, s = np.cos(u), np.sin(u)
        return np.stack([np.sign(c) * np.abs(c) ** 0.3, 0.5 * np.sign(s) * np.abs(s) ** 0.3], 1)
    if shape == "figure8":
        return np.stack([np.sin(u), 0.5 * np.sin(2 * u)], axis=1)
    if shape == "limacon":
        r = 1.0 + 0.5 * np.cos(u)
        return np.stack([r * np.cos(u), 0.8 * r * np.sin(u)], axis=1)
    if shape == "wobbly":
        k = np.arange(2, 6)
        amp = rng.uniform(0.05, 0.15, (2, k.size)) / k
        phase = rng.uniform(0, 2 * np.pi, (2, k.size))
        r = 1.0 + (amp[0] * np.sin(np.outer(u, k) + phase[0])).sum(axis=1)
        r2 = 0.7 + (amp[1] * np.sin(np.outer(u, k) + phase[1])).sum(axis=1)
        return np.stack([r * np.cos(u), r2 * np.sin(u)], axis=1)
    msg = f"unknown shape {shape!r}"
    raise ValueError(msg)


def _distance(family: PlanarFamily, t: np.ndarray, phase: float) -> np.ndarray:
    """Distance driven by time ``t`` (metres) under the family's speed profile."""
    v0, w = family.speed_m_s, 2 * np.pi / 40.0
    if family.speed == "constant":
        return v0 * t
    if family.speed == "sinusoidal":
        # v = v0 (1 + 0.6 sin(w t + phase)), integrated.
        return v0 * (t - 0.6 / w * (np.cos(w * t + phase) - np.cos(phase)))
    if family.speed == "stop_and_go":
        # Drive 12 s, stand 4 s, smoothly: v = v0 * clip(1.4 * sin, 0, 1) sampled finely.
        fine = np.arange(0.0, t.max() + 0.02, 0.01)
        v = v0 * np.clip(1.6 * np.sin(2 * np.pi * fine / 16.0 + phase) + 0.6, 0.0, 1.0)
        d = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.01)))
        out: np.ndarray = np.interp(t, fine, d)
        return out
    msg = f"unknown speed profile {family.speed!r}"
    raise ValueError(msg)


def _robot(
    family: PlanarFamily, t: np.ndarray, shape_seed: int, phase: float
) -> tuple[np.ndarray, Rotation]:
    """The robot's positions (N, 3) and orientations at times ``t``."""
    u_table = np.linspace(0.0, 2 * np.pi, 4001)
    pts = _curve(family.shape, u_table, np.random.default_rng(shape_seed)) * family.size_m
    arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))))
    s = np.mod(_distance(family, t, phase), arc[-1])
    u = np.interp(s, arc, u_table)
    xy = _curve(family.shape, u, np.random.default_rng(shape_seed)) * family.size_m
    ahead = _curve(family.shape, u + 1e-4, np.random.default_rng(shape_seed)) * family.size_m
    heading = np.unwrap(np.arctan2(ahead[:, 1] - xy[:, 1], ahead[:, 0] - xy[:, 0]))
    if family.holonomic:
        heading = heading + np.radians(40.0) * np.sin(2 * np.pi * t / 23.0 + phase)
    xyz = np.column_stack([xy, np.full(t.shape, 0.25)])
    return xyz, Rotation.from_euler("z", heading[:, None])


def make_planar_recording(rng: np.random.Generator, family: PlanarFamily) -> Recording:
    """Generate one planar recording of ``family`` (time offset 0; the device offset known)."""
    shape_seed = int(rng.integers(2**32))
    phase = float(rng.uniform(0, 2 * np.pi))
    device = SimilarityTransform(
        Rotation.from_euler(
            "xyz",
            [
                family.device_tilt_deg * rng.choice([-1, 1]),
                family.device_tilt_deg * rng.choice([-1, 1]),
                family.device_yaw_deg,
            ],
            degrees=True,
        ).as_matrix(),
        np.array([0.15, -0.05, 0.3]) * rng.uniform(0.5, 1.5, 3),
    )
    t_ref = np.arange(0.0, family.duration_s, 1.0 / family.reference_rate_hz)
    p_body, r_body = _robot(family, t_ref, shape_seed, phase)
    reference = Trajectory(
        T0_NS + np.rint(t_ref * 1e9).astype(np.int64),
        p_body,
        r_body.as_quat(),
        name="reference",
        source="synthetic",
        frame_id="world",
    )
    t_est = np.arange(0.5, family.duration_s - 0.5, 1.0 / family.estimate_rate_hz)
    t_est = t_est + rng.uniform(-1e-3, 1e-3, t_est.shape)
    p_b, r_b = _robot(family, t_est, shape_seed, phase)
    r_sensor = r_b * Rotation.from_matrix(np.array(device.rotation))
    p_sensor = p_b + r_b.apply(np.array(device.translation))
    world = Rotation.from_euler("xyz", rng.uniform(-180, 180, 3), degrees=True)
    yaw_rate = family.yaw_drift_deg_per_min * rng.choice([-1, 1]) / 60.0
    heading_error = np.radians(
        yaw_rate * t_est
        + np.cumsum(rng.normal(0.0, 0.02, t_est.size)) * np.sqrt(30.0 / family.estimate_rate_hz)
    )
    drift_r = Rotation.from_euler("z", heading_error[:, None])
    if family.drift_model == "odometry":
        # Integrate the sensor's steps turned by the heading error, and a slow scale error.
        steps = np.diff(p_sensor, axis=0)
        turned = drift_r[:-1].apply(steps) * (1.0 + family.drift_m_per_min / 60.0)
        p_drifted = p_sensor[0] + np.concatenate((np.zeros((1, 3)), np.cumsum(turned, axis=0)))
    else:
        direction = rng.normal(size=3)
        direction[2] *= 0.1
        direction /= np.linalg.norm(direction)
        drift_t = np.outer(t_est / 60.0 * family.drift_m_per_min, direction)
        p_drifted = drift_r.apply(p_sensor) + drift_t
    p_est = world.apply(p_drifted) + rng.uniform(-5, 5, 3)
    p_est = p_est + rng.normal(0.0, family.position_noise_m, p_est.shape)
    noise = Rotation.from_rotvec(
        np.radians(rng.normal(0.0, family.orientation_noise_deg, (t_est.size, 3)))
    )
    estimate = Trajectory(
        T0_NS + np.rint(t_est * 1e9).astype(np.int64),
        p_est,
        (world * drift_r * r_sensor * noise).as_quat(),
        name="estimate",
        source="synthetic",
        frame_id="odom",
    )
    return Recording(reference, estimate, 0.0, device, 1.0)
