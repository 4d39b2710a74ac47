"""Benchmark: reading and evaluating a 4000 x 4000 cell map against a 5,000-segment plan.

Run by hand:

    .venv/bin/python -m benchmarks.maps [--cells 4000] [--rooms 50] [--repeat 3] [--json FILE]

The plan: ``rooms`` x ``rooms`` square rooms, each wall piece one segment (50 x 50 rooms:
5,100 segments, 20 km of wall). The map: 0.05 m cells, the plan's walls drawn 0.4 % short
and turned 0.3° (as a SLAM map drifts), every cell inside the building free, a margin
unknown; written as map_server's YAML and PGM (16 MB). The table gives the best wall time
of ``--repeat`` runs of reading the files (:func:`loceval.maps.read_map`) and of
evaluating (:func:`loceval.maps.evaluate_map`: wall cells, both fits, every figure), and
the figures found, so a wrong result cannot pass as a fast one.

The evaluation runs as the ``loceval`` command and the service run it: OpenBLAS on one
thread (``service/__init__.py`` sets it for them; see its docstring; set here too). With
OpenBLAS's default threads on a loaded two-core machine the same run took 3.2 s of wall
time for 1.9 s of CPU (its idle threads spin against the other processes).

Measured (2 cores shared with other work, load average 4-5; best of 3):
before the bucket table (KD-tree for every point) 1.5-1.65 s CPU; with it
(:mod:`loceval.maps.buckets`) 0.80 s wall, 0.80 s CPU in total (read 0.04 s).
"""

from __future__ import annotations

import os

# before numpy loads: OpenBLAS on one thread, as service/__init__.py sets it for the command
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from loceval.core.geometry import SimilarityTransform
from loceval.maps import evaluate_map, read_map

RESOLUTION_M = 0.05
SCALE = 0.996
YAW_DEG = 0.3


def make_plan(rooms: int, room_m: float) -> np.ndarray:
    """(K, 2, 2) segments of ``rooms`` x ``rooms`` square rooms, one segment per wall piece."""
    edges = np.arange(rooms + 1) * room_m
    x0, y = np.meshgrid(edges[:-1], edges)
    horizontal = np.stack([np.c_[x0.ravel(), y.ravel()], np.c_[x0.ravel() + room_m, y.ravel()]], 1)
    x, y0 = np.meshgrid(edges, edges[:-1])
    vertical = np.stack([np.c_[x.ravel(), y0.ravel()], np.c_[x.ravel(), y0.ravel() + room_m]], 1)
    return np.concatenate([horizontal, vertical])


def write_map(folder: Path, plan: np.ndarray, cells: int, margin_m: float) -> Path:
    """Draw the plan's walls, distorted, into a PGM and write map_server's YAML beside it."""
    a = math.radians(YAW_DEG)
    rotation = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    start, end = plan[:, 0], plan[:, 1]
    count = int(np.ceil(np.linalg.norm(end - start, axis=1).max() / (RESOLUTION_M / 4))) + 1
    t = np.linspace(0.0, 1.0, count)
    points = (start[:, None, :] + t[None, :, None] * (end - start)[:, None, :]).reshape(-1, 2)
    points = SCALE * points @ rotation.T + margin_m
    image = np.full((cells, cells), 205, dtype=np.uint8)  # unknown
    inner = round(margin_m / RESOLUTION_M)
    image[inner:-inner, inner:-inner] = 254  # free inside the building
    ij = np.floor(points / RESOLUTION_M).astype(np.intp)
    ok = ((ij >= 0) & (ij < cells)).all(axis=1)
    image[ij[ok, 1], ij[ok, 0]] = 0  # occupied
    pgm = folder / "map.pgm"
    pgm.write_bytes(f"P5\n{cells} {cells}\n255\n".encode() + image[::-1].tobytes())
    yaml = folder / "map.yaml"
    yaml.write_text(
        f"image: map.pgm\nresolution: {RESOLUTION_M}\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n",
        encoding="utf-8",
    )
    return yaml


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print (or write) the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=4000)
    parser.add_argument("--rooms", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    margin_m = 2.0
    room_m = (args.cells * RESOLUTION_M - 2 * margin_m - 1.0) / args.rooms
    plan = make_plan(args.rooms, room_m)
    with tempfile.TemporaryDirectory() as tmp:
        yaml = write_map(Path(tmp), plan, args.cells, margin_m)
        reads, evals, cpu = [], [], []
        for _ in range(args.repeat):  # a few timed repetitions
            c0, t0 = time.process_time(), time.perf_counter()
            grid = read_map(str(yaml))
            t1 = time.perf_counter()
            result = evaluate_map(grid, plan + margin_m, SimilarityTransform.identity())
            t2 = time.perf_counter()
            cpu.append(time.process_time() - c0)
            reads.append(t1 - t0)
            evals.append(t2 - t1)
    row = {
        "cells": f"{args.cells} x {args.cells}",
        "segments": len(plan),
        "wall_cells": len(result.cells_xy),
        "read_s": min(reads),
        "evaluate_s": min(evals),
        "total_s": min(r + e for r, e in zip(reads, evals, strict=True)),
        "total_cpu_s": min(cpu),
        "placed_rmse_m": result.placed.rmse,
        "similarity_scale": result.similarity[0].scale,
        "similarity_rmse_m": result.similarity[1].rmse,
        "plan_coverage": result.similarity[1].plan_coverage,
    }
    text = json.dumps(row, indent=2)
    if args.json is not None:
        args.json.write_text(text + "\n", encoding="utf-8")
    sys.stdout.write(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
