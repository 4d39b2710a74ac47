"""Fixtures for the core's tests: smooth random 3D trajectories."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.trajectory import Trajectory

T0_NS = 1_700_000_000 * 10**9


def smooth_trajectory(
    rng: np.random.Generator, *, n: int = 500, rate_hz: float = 100.0, name: str = "truth"
) -> Trajectory:
    """A smooth random 3D walk with orientations: sums of sines, a few metres across."""
    t = np.arange(n) / rate_hz
    freq = rng.uniform(0.05, 0.4, (3, 3))
    amp = rng.uniform(0.5, 3.0, (3, 3)) * np.array([[1.0], [1.0], [0.2]])
    phase = rng.uniform(0, 2 * np.pi, (3, 3))
    positions = np.stack(
        [(amp[k] * np.sin(2 * np.pi * freq[k] * t[:, None] + phase[k])).sum(1) for k in range(3)],
        axis=1,
    )
    angles = np.stack(
        [0.3 * np.sin(0.2 * t + phase[0, 0]), 0.2 * np.sin(0.3 * t), np.unwrap(0.5 * t)], axis=1
    )
    quat = Rotation.from_euler("xyz", angles).as_quat()
    stamps = T0_NS + np.rint(t * 1e9).astype(np.int64)
    return Trajectory(stamps, positions, quat, name=name, source=f"{name}.tum", frame_id="map")


@pytest.fixture
def truth(rng: np.random.Generator) -> Trajectory:
    """Return a 5 s, 100 Hz smooth trajectory."""
    return smooth_trajectory(rng)
