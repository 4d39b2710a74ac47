"""Benchmark: CAD export time and file size for a 100,000-pose evaluation.

Run by hand:

    .venv/bin/python -m benchmarks.cad [--poses 100000] [--repeat 3] [--json FILE]

The evaluation: a 1000 s walk at 100 Hz through several rooms (ground truth, 100,000 poses)
and one estimate at the same rate with slow drift (a smoothed random walk, ~5 cm) plus 1 mm
white noise, aligned with SE(3). Every CAD format (paths.dxf, paths.3dm, paths.3dm.json,
paths.glb, paths.ifc) is exported with the default 1 mm simplification and without
simplification (``simplify_m=0``), with a national-grid-sized site offset in EPSG:25832
(the IFC keeps evaluation-frame coordinates and carries the offset in its map
conversion). The table gives the best wall time of ``--repeat`` runs (each export places
the paths itself, so the time includes the placement), the file size, the vertices
written (both polylines) and the largest deviation the simplification introduced.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from exporters import ARTIFACTS
from exporters.cad.placement import parse_site, place_evaluation
from exporters.options import ExportOptions
from loceval.evaluation import EvaluationResult, evaluate
from loceval.trajectory import Trajectory

FORMATS = ("paths.dxf", "paths.3dm", "paths.3dm.json", "paths.glb", "paths.ifc")
SITE = "512340.25 5403210.5 112.3 37.5"
CRS = "EPSG:25832"
RATE_HZ = 100.0


def make_evaluation(poses: int, seed: int = 20240601) -> EvaluationResult:
    """Return the benchmark evaluation: ground truth and one drifting, jittery estimate."""
    rng = np.random.default_rng(seed)
    t = np.arange(poses) / RATE_HZ
    s = t / t[-1] * 8 * 2 * np.pi  # eight laps through the rooms
    x = 10.0 * np.cos(s) + 3.0 * np.cos(7 * s)
    y = 6.0 * np.sin(s) + 2.0 * np.sin(5 * s)
    z = 1.3 + 0.05 * np.sin(31 * s)
    truth_xyz = np.stack([x, y, z], axis=1)
    yaw = np.unwrap(np.arctan2(np.gradient(y), np.gradient(x)))
    quat = Rotation.from_euler("z", yaw[:, None]).as_quat()
    stamps = (1_700_000_000 * 10**9 + np.rint(t * 1e9)).astype(np.int64)
    truth = Trajectory(stamps, truth_xyz, quat, name="ground truth", frame_id="map")
    drift = gaussian_filter1d(np.cumsum(rng.normal(0, 0.002, (poses, 3)), axis=0), 500, axis=0)
    jitter = rng.normal(0.0, 0.001, (poses, 3))
    estimate = Trajectory(stamps, truth_xyz + drift + jitter, quat, name="SLAM", source="slam")
    return evaluate(truth, [estimate])


@dataclass(frozen=True, slots=True)
class Row:
    """One format at one tolerance."""

    format: str
    simplify_m: float
    seconds: float
    bytes: int
    vertices: int
    max_deviation_m: float
    placement_seconds: float


def measure(result: EvaluationResult, simplify_m: float, repeat: int) -> list[Row]:
    """Export every CAD format and return time, size, vertices and deviation per format."""
    options = ExportOptions(
        site=parse_site(SITE), crs=CRS, simplify_m=simplify_m, evaluation_id="bench"
    )
    start = time.perf_counter()
    placement = place_evaluation(result, options)
    place_s = time.perf_counter() - start
    vertices = sum(len(p.vertices) for p in placement.paths)
    rows = []
    for name in FORMATS:
        export = ARTIFACTS[name].load()
        best = float("inf")
        size = 0
        for _ in range(repeat):
            start = time.perf_counter()
            data = export(result, options)
            best = min(best, time.perf_counter() - start)
            size = len(data)
        rows.append(Row(name, simplify_m, best, size, vertices, placement.max_deviation_m, place_s))
    return rows


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", type=Path, help="also write the rows as JSON here")
    args = parser.parse_args(argv)

    start = time.perf_counter()
    result = make_evaluation(args.poses)
    print(f"evaluation of {args.poses} poses: {time.perf_counter() - start:.2f} s")
    rows = measure(result, 0.001, args.repeat) + measure(result, 0.0, args.repeat)
    header = (
        f"{'format':<15} {'simplify':>9} {'time s':>8} {'size MB':>9} {'vertices':>9} "
        f"{'max dev mm':>10} {'place s':>8}"
    )
    print(header)
    print("-" * len(header))
    for row in rows:
        print(
            f"{row.format:<15} {row.simplify_m:>9g} {row.seconds:>8.2f} "
            f"{row.bytes / 1e6:>9.2f} {row.vertices:>9} "
            f"{row.max_deviation_m * 1000:>10.3f} {row.placement_seconds:>8.2f}"
        )
    if args.json is not None:
        args.json.write_text(json.dumps([asdict(r) for r in rows], indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
