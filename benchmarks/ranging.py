"""Time the ranging evaluation and both positioning solvers on generated ranges.

Run by hand: ``.venv/bin/python -m benchmarks.ranging [--repeat N] [--ranges N]``.
Target on a 2-core machine: 100,000 ranges from 20 anchors (10 Hz each, 500 s walk,
100 Hz reference with orientations): ranging evaluation + NLLS + Min-Max under 3 s, in
2D and in 3D. The whole pipeline (:func:`loceval.radio_evaluation.evaluate_radio`: the same plus
the evaluation of both solvers' positions, as ``loceval ranging`` runs it) is timed too, and
reading the two CSV files separately.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.radio.multilateration import make_epochs, solve_minmax, solve_nlls
from loceval.radio.ranging import evaluate_ranging
from loceval.radio_evaluation import RangingConfig, evaluate_radio
from loceval.readers.radio import Anchors, Ranges, read_anchors, read_ranges
from loceval.trajectory import Trajectory

TARGET_S = 3.0
N_ANCHORS = 20
T0_NS = 1_700_000_000 * 10**9


def make_case(n_ranges: int) -> tuple[Trajectory, Ranges]:
    """Return a 100 Hz reference and ``n_ranges`` noisy ranges from 20 anchors at 10 Hz."""
    rng = np.random.default_rng(17)
    ticks = n_ranges // N_ANCHORS
    duration_s = ticks / 10.0
    t_ref = np.arange(int(duration_s * 100) + 20) / 100.0
    s = t_ref / duration_s * 6 * np.pi
    xyz = np.column_stack((20 + 18 * np.sin(s), 10 + 8 * np.sin(2 * s), 1.2 + 0.1 * np.sin(s)))
    yaw = np.arctan2(np.gradient(xyz[:, 1]), np.gradient(xyz[:, 0]))
    reference = Trajectory(
        T0_NS + np.rint(t_ref * 1e9).astype(np.int64),
        xyz,
        Rotation.from_euler("z", yaw[:, None]).as_quat(),
        name="reference",
    )
    low, high = np.array([0.0, 0.0, 0.3]), np.array([40.0, 20.0, 3.0])
    anchors_xyz = rng.uniform(low, high, (N_ANCHORS, 3))
    anchors = Anchors(tuple(f"A{k:02d}" for k in range(N_ANCHORS)), anchors_xyz)
    t = (np.arange(ticks)[:, None] / 10.0 + np.arange(N_ANCHORS)[None, :] * 0.004).ravel()
    anchor = np.tile(np.arange(N_ANCHORS), ticks)
    tag = np.column_stack([np.interp(t, t_ref, xyz[:, k]) for k in range(3)])
    true = np.linalg.norm(tag - anchors_xyz[anchor], axis=1)
    nlos = rng.uniform(size=t.size) < 0.03
    measured = true + 0.1 + rng.normal(0, 0.1, t.size) + nlos * rng.uniform(2, 8, t.size)
    ranges = Ranges(
        anchors, T0_NS + np.rint(t * 1e9).astype(np.int64), anchor, np.maximum(measured, 0.0)
    )
    return reference, ranges


def run_core(reference: Trajectory, ranges: Ranges, dims: int) -> float:
    """Return the wall time of ranging evaluation + epochs + NLLS + Min-Max."""
    start = time.perf_counter()
    evaluate_ranging(reference, ranges)
    epochs = make_epochs(ranges, dims=dims, tag_height_m=1.2)
    solve_nlls(epochs)
    solve_minmax(epochs)
    return time.perf_counter() - start


def run_pipeline(reference: Trajectory, ranges: Ranges, dims: int) -> float:
    """Return the wall time of the whole pipeline: ranging, both solvers, their evaluation."""
    start = time.perf_counter()
    evaluate_radio(reference, ranges, RangingConfig(dims=dims, tag_height_m=1.2))
    return time.perf_counter() - start


def time_reading(ranges: Ranges) -> float:
    """Write the ranges as CSV and return the time to read anchors and ranges back."""
    with tempfile.TemporaryDirectory() as folder:
        anchors_path = Path(folder) / "anchors.csv"
        ranges_path = Path(folder) / "ranges.csv"
        a = ranges.anchors
        rows = zip(a.ids, a.positions_xyz.tolist(), strict=True)
        text = "".join(f"{i},{p[0]!r},{p[1]!r},{p[2]!r}\n" for i, p in rows)
        anchors_path.write_text("id,x,y,z\n" + text, encoding="utf-8")
        seconds = ranges.stamps_ns // 10**9
        nanos = ranges.stamps_ns % 10**9
        ids = np.array(a.ids)[ranges.anchor_index]
        columns = (seconds.tolist(), nanos.tolist(), ids.tolist(), ranges.range_m.tolist())
        cells = zip(*columns, strict=True)
        lines = [f"{s}.{n:09d},{i},{r!r}" for s, n, i, r in cells]
        ranges_path.write_text("t,anchor_id,range_m\n" + "\n".join(lines) + "\n", encoding="utf-8")
        start = time.perf_counter()
        read_ranges(ranges_path, read_anchors(anchors_path))
        return time.perf_counter() - start


def main() -> int:
    """Generate the case, time each dimension, print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranges", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=5)
    opts = parser.parse_args()
    reference, ranges = make_case(opts.ranges)
    print(f"{len(ranges)} ranges from {N_ANCHORS} anchors, reference {len(reference)} poses")
    print(f"{'dims':>4} {'median s':>9} {'min s':>7} target")
    for dims in (2, 3):
        times = [run_core(reference, ranges, dims) for _ in range(opts.repeat)]
        med = statistics.median(times)
        verdict = "ok" if med < TARGET_S else "MISSED"
        print(f"{dims:>4} {med:>9.3f} {min(times):>7.3f} < {TARGET_S} s {verdict}")
    for dims in (2, 3):
        times = [run_pipeline(reference, ranges, dims) for _ in range(opts.repeat)]
        med = statistics.median(times)
        print(f"{dims:>4} {med:>9.3f} {min(times):>7.3f} whole pipeline (evaluate_radio)")
    print(f"reading anchors + ranges CSV: {time_reading(ranges):.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
