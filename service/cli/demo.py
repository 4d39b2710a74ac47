"""A synthetic recording for ``loceval demo``: a walk through two rooms and two systems.

It lets a new user see every output without data of their own; the numbers are not
meaningful beyond that.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.core.arrays import FloatArray

__all__ = ["write_demo_recording"]

_SEED = 20240601


def write_demo_recording(folder: Path) -> dict[str, Path]:
    """Write a ground truth and two estimates as TUM files into ``folder``.

    The ground truth is a 60 s, 100 Hz walk (a loop with a detour, 1.2-1.4 m high); the
    estimates run at 30 Hz and 25 Hz in a rotated, shifted frame with noise and drift,
    and the second loses tracking for two seconds.

    Returns:
        The paths by role: ``reference``, ``RTAB-Map``, ``ISAAC``.
    """
    rng = np.random.default_rng(_SEED)
    folder.mkdir(parents=True, exist_ok=True)
    t = np.arange(6000) / 100.0
    s = t / t[-1] * 2 * np.pi
    positions = np.stack(
        [4.0 * np.cos(s) + 1.5 * np.cos(3 * s), 3.0 * np.sin(s), 1.3 + 0.1 * np.sin(5 * s)],
        axis=1,
    )
    yaw = np.unwrap(np.arctan2(np.gradient(positions[:, 1]), np.gradient(positions[:, 0])))
    body = Rotation.from_euler("z", yaw[:, None])
    stamps = 1_700_000_000.0 + t
    paths = {"reference": folder / "optitrack.tum"}
    _write_tum(paths["reference"], stamps, positions, body.as_quat())
    frame = Rotation.from_euler("z", 30, degrees=True)
    for name, every, sigma, drift, lost in (
        ("RTAB-Map", 3, 0.02, 0.30, None),
        ("ISAAC", 4, 0.05, 0.05, (30.0, 32.0)),
    ):
        idx = np.arange(0, len(t), every)
        if lost is not None:
            idx = idx[(t[idx] < lost[0]) | (t[idx] > lost[1])]
        k = np.linspace(0.0, 1.0, idx.size)[:, None]
        noisy = positions[idx] + rng.normal(0.0, sigma, (idx.size, 3)) + drift * k
        # Heading noise of about a degree and a slowly growing heading drift.
        wobble = Rotation.from_rotvec(
            rng.normal(0.0, np.radians(sigma * 10), (idx.size, 3))
            + np.array([0.0, 0.0, np.radians(3.0)]) * drift * k
        )
        paths[name] = folder / f"{name.lower().replace('-', '_')}.tum"
        _write_tum(
            paths[name],
            stamps[idx],
            frame.apply(noisy) + np.array([2.0, -1.0, 0.0]),
            (frame * body[idx] * wobble).as_quat(),
        )
    return paths


def _write_tum(path: Path, stamps: FloatArray, xyz: FloatArray, quat: FloatArray) -> None:
    table = np.column_stack([stamps, xyz, quat])
    np.savetxt(path, table, fmt="%.6f", header="timestamp tx ty tz qx qy qz qw")
