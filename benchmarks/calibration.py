"""Time the clock and device-offset estimation on a long generated recording.

Run by hand: ``.venv/bin/python -m benchmarks.calibration [--repeat N]``.
Target on a 2-core machine: 200,000 reference poses (120 Hz, about 28 minutes, with tracking
losses) against 50,000 estimate poses (30 Hz, drifting, noisy, 45 ms late): the time offset
(coarse search over every lag, then least squares) plus the device offset with the time
offset refined jointly, under 2 s in process (reading the files is benchmarks/core.py's).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.calibration.clock import estimate_time_offset
from loceval.calibration.handeye import estimate_device_offset
from loceval.trajectory import Trajectory

N_REF, N_EST, TARGET_S = 200_000, 50_000, 2.0
DELAY_S = -0.045
OFFSET_T = np.array([0.062, -0.035, 0.081])
OFFSET_R = Rotation.from_euler("xyz", [12.0, -7.0, 95.0], degrees=True)


def _motion(t: np.ndarray, rng_seed: int) -> tuple[np.ndarray, Rotation]:
    """Handheld motion: sums of sines, +/- 30 deg about every axis, never repeating."""
    rng = np.random.default_rng(rng_seed)
    freq = rng.uniform(0.05, 0.5, (6, 4))
    phase = rng.uniform(0, 2 * np.pi, (6, 4))
    waves = np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None]).mean(axis=2)
    xyz = waves[:, :3] * np.array([1.2, 1.0, 0.4]) + np.array([0.0, 0.0, 1.3])
    return xyz, Rotation.from_euler("ZYX", 30.0 * waves[:, 3:], degrees=True)


def make_pair(seed: int = 7) -> tuple[Trajectory, Trajectory]:
    """Return the 200k-pose reference and the 50k-pose estimate."""
    rng = np.random.default_rng(seed)
    t_ref = np.arange(N_REF + 2000) / 120.0
    lost = np.zeros(t_ref.shape, dtype=bool)
    for start in rng.uniform(10, t_ref[-1] - 10, 20):  # 20 tracking losses
        lost |= (t_ref > start) & (t_ref < start + rng.uniform(0.3, 1.5))
    t_ref = t_ref[~lost][:N_REF]
    xyz, rot = _motion(t_ref, seed)
    t0 = 1_700_000_000 * 10**9
    reference = Trajectory(t0 + np.rint(t_ref * 1e9).astype(np.int64), xyz, rot.as_quat())
    t_est = 0.5 + np.arange(N_EST) / 30.0
    xyz_b, rot_b = _motion(t_est, seed)
    rot_s = rot_b * OFFSET_R
    xyz_s = xyz_b + rot_b.apply(OFFSET_T) + np.outer(t_est / 60.0 * 0.01, [0.6, 0.8, 0.0])
    xyz_s += rng.normal(0, 0.001, xyz_s.shape)
    noise = Rotation.from_rotvec(np.radians(rng.normal(0, 0.3, (N_EST, 3))))
    stamps = t0 + np.rint((t_est - DELAY_S) * 1e9).astype(np.int64)
    return reference, Trajectory(stamps, xyz_s, (rot_s * noise).as_quat())


def main() -> int:
    """Generate the recording, time the estimation, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    opts = parser.parse_args()
    reference, estimate = make_pair()
    times = []
    for _ in range(opts.repeat):
        start = time.perf_counter()
        clock = estimate_time_offset(reference, estimate)
        device = estimate_device_offset(reference, estimate, time_offset_s=clock.value_s)
        times.append(time.perf_counter() - start)
    err_t_mm = (np.array(device.translation_m) - OFFSET_T) * 1e3
    med = statistics.median(times)
    print(f"{len(reference)} reference / {len(estimate)} estimate poses")
    print(f"time offset {clock.value_s * 1e3:.3f} ms (true {DELAY_S * 1e3:.1f} ms), ", end="")
    print(f"joint {device.time_offset_s * 1e3:.3f} ms; translation error {err_t_mm.round(3)} mm")
    verdict = "ok" if med < TARGET_S else "MISSED"
    print(f"median {med:.3f} s, min {min(times):.3f} s (target < {TARGET_S} s) {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
