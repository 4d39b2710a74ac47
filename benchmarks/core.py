"""Time the whole ``loceval evaluate --json`` process on generated TUM files.

Run by hand: ``.venv/bin/python -m benchmarks.core [--workdir DIR] [--repeat N]``.
Targets on a 2-core machine: 200,000 reference / 50,000 estimate poses under 1.2 s wall,
1,000,000 / 200,000 under 5 s (read + associate + align + ATE + RPE, process start included).
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

CASES = ((200_000, 50_000, 1.2), (1_000_000, 200_000, 5.0))


def write_pair(folder: Path, n_ref: int, n_est: int) -> tuple[Path, Path]:
    """Write a reference at 200 Hz and a noisy, rotated estimate sampled from it."""
    ref_path = folder / f"ref_{n_ref}.tum"
    est_path = folder / f"est_{n_ref}_{n_est}.tum"
    if ref_path.exists() and est_path.exists():
        return ref_path, est_path
    rng = np.random.default_rng(7)
    t = 1_700_000_000.0 + np.arange(n_ref) / 200.0
    s = np.linspace(0, 40 * np.pi, n_ref)
    xyz = np.stack([10 * np.cos(s / 7), 6 * np.sin(s / 5), 1.2 + 0.2 * np.sin(s)], 1)
    quat = Rotation.from_euler("z", s[:, None]).as_quat()
    np.savetxt(ref_path, np.column_stack([t, xyz, quat]), fmt="%.9f")
    idx = np.sort(rng.choice(n_ref, n_est, replace=False))
    frame = Rotation.from_euler("z", 25, degrees=True)
    est_xyz = frame.apply(xyz[idx] + rng.normal(0, 0.03, (n_est, 3))) + np.array([1.0, 2.0, 0.0])
    est_quat = (frame * Rotation.from_quat(quat[idx])).as_quat()
    np.savetxt(est_path, np.column_stack([t[idx], est_xyz, est_quat]), fmt="%.9f")
    return ref_path, est_path


def time_run(args: list[str]) -> float:
    """Return the wall time of one CLI process, checking its JSON output."""
    start = time.perf_counter()
    out = subprocess.run(args, capture_output=True, text=True, check=True)
    elapsed = time.perf_counter() - start
    json.loads(out.stdout)
    return elapsed


def main() -> int:
    """Generate the files, time each case, print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", type=Path, default=Path("benchmarks/_work"))
    parser.add_argument("--repeat", type=int, default=5)
    opts = parser.parse_args()
    opts.workdir.mkdir(parents=True, exist_ok=True)
    cli = str(Path(sys.executable).with_name("loceval"))
    print(
        f"{'reference':>10} {'estimate':>9} {'associate':>11} {'median s':>9} {'min s':>7} target"
    )
    for n_ref, n_est, target in CASES:
        ref, est = write_pair(opts.workdir, n_ref, n_est)
        for method in ("interpolate", "nearest"):
            argv = [cli, "evaluate", str(ref), str(est), "--json", "--associate", method]
            times = [time_run(argv) for _ in range(opts.repeat)]
            med = statistics.median(times)
            verdict = "ok" if med < target else "MISSED"
            print(f"{n_ref:>10} {n_est:>9} {method:>11} {med:>9.3f} {min(times):>7.3f} "
                  f"< {target} s {verdict}")  # fmt: skip
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"peak RSS of the largest run: {peak_mb:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
