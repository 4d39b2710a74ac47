"""A generated two-room office as IFC, DXF plan and Z-up GLB, and a run that fails in one room.

The same walls (:data:`tests.exporters.ifcfactory.OFFICE_WALLS`) three ways: the IFC with
its two named spaces (``2.13 Meeting``, ``2.14 Office``), a millimetre DXF plan whose
rooms are closed outlines labelled by two texts each (number above name), and a GLB written
by trimesh from the Z-up boxes without turning them (as trimesh and many exporters write
it: the glTF convention would be Y up).

:func:`office_run` walks the ground truth through both rooms at 20 Hz; the estimate is the
ground truth shifted by a known error: 0.010 m everywhere, plus two smooth bumps to 0.060 m
and 0.045 m while the walker is in the office, so with a tolerance of 0.025 m the system
fails in the office only, in two stretches.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
from loceval.registration.alignment import AlignMethod
from loceval.trajectory import Trajectory
from tests.exporters.ifcfactory import (
    OFFICE_HEIGHT_M,
    OFFICE_ROOMS,
    OFFICE_WALLS,
    wall_corners,
    write_office,
)

__all__ = [
    "BASE_ERROR_M",
    "TOLERANCE_M",
    "evaluate_office",
    "office_run",
    "room_of",
    "write_office",
    "write_office_glb",
    "write_office_plan",
]

TOLERANCE_M = 0.025
BASE_ERROR_M = 0.010
RATE_HZ = 20.0
SPEED_M_S = 0.5
HEIGHT_M = 1.2
ROUTE = [
    (1.5, 1.5), (3.5, 1.5), (3.5, 4.5), (1.5, 4.5), (1.5, 3.0), (4.0, 3.0), (5.0, 3.0),
    (7.5, 3.0), (8.5, 1.5), (8.5, 4.5), (6.5, 4.5), (6.5, 3.0), (5.0, 3.0), (2.5, 3.0),
]  # fmt: skip
"""The walker's corners: a loop of the meeting room, through the door, a loop of the office."""
BUMPS = [((8.5, 1.6), (8.5, 4.4), 0.050), ((8.4, 4.5), (6.6, 4.5), 0.035)]
"""(from, to, height): the error rises by ``height`` (a raised cosine) along these legs."""


def write_office_plan(path: Path) -> Path:
    """Write the office as a millimetre DXF plan: walls, room outlines, two texts per room."""
    import ezdxf
    from ezdxf import units

    doc = ezdxf.new("R2013", units=units.MM)
    msp = doc.modelspace()
    for wall in OFFICE_WALLS:
        corners = wall_corners(*wall) * 1000.0
        msp.add_lwpolyline(corners.tolist(), close=True, dxfattribs={"layer": "A-WALL"})
    for (number, name), (x0, x1, y0, y1) in OFFICE_ROOMS.items():
        ring = np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)]) * 1000.0
        msp.add_lwpolyline(ring.tolist(), close=True, dxfattribs={"layer": "A-AREA"})
        cx, cy = (x0 + x1) * 500.0, (y0 + y1) * 500.0
        msp.add_text(
            number, height=250, dxfattribs={"layer": "A-AREA-IDEN", "insert": (cx, cy + 150)}
        )
        msp.add_text(
            name, height=250, dxfattribs={"layer": "A-AREA-IDEN", "insert": (cx, cy - 250)}
        )
    doc.saveas(path)
    return path


def write_office_glb(path: Path) -> Path:
    """Write the office's walls as a GLB by trimesh, from Z-up boxes (not turned to Y up)."""
    import trimesh

    boxes = []
    for wall in OFFICE_WALLS:
        corners = wall_corners(*wall)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        box = trimesh.creation.box(extents=(hi[0] - lo[0], hi[1] - lo[1], OFFICE_HEIGHT_M))
        box.apply_translation([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, OFFICE_HEIGHT_M / 2])
        boxes.append(box)
    trimesh.util.concatenate(boxes).export(path)
    return path


def _raised(points: np.ndarray, start: tuple[float, float], end: tuple[float, float]) -> np.ndarray:
    """Return 0..1 along the leg start -> end (a raised cosine), 0 off it (0.1 m wide)."""
    a, b = np.array(start), np.array(end)
    d = b - a
    s = np.clip(((points - a) @ d) / (d @ d), -1.0, 2.0)
    off = np.linalg.norm(points - (a + np.outer(np.clip(s, 0.0, 1.0), d)), axis=1)
    on = (s >= 0.0) & (s <= 1.0) & (off < 0.1)
    return np.where(on, 0.5 - 0.5 * np.cos(2 * math.pi * np.clip(s, 0.0, 1.0)), 0.0)


def office_run() -> tuple[Trajectory, Trajectory, np.ndarray]:
    """Return the ground truth, the estimate and the estimate's known error (metres) per pose.

    The estimate is the ground truth shifted along (1, 1, 0) / sqrt(2) by the error, so with
    no alignment its ATE is exactly that error.
    """
    corners = np.array(ROUTE, dtype=np.float64)
    legs = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    along = np.concatenate(([0.0], np.cumsum(legs)))
    n = int(along[-1] / SPEED_M_S * RATE_HZ) + 1
    s = np.linspace(0.0, along[-1], n)
    xy = np.column_stack([np.interp(s, along, corners[:, 0]), np.interp(s, along, corners[:, 1])])
    truth_xyz = np.column_stack([xy, np.full(n, HEIGHT_M)])
    error = np.full(n, BASE_ERROR_M)
    for start, end, height in BUMPS:
        error += height * _raised(xy, start, end)
    direction = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    stamps = 1_700_000_000_000_000_000 + np.round(np.arange(n) / RATE_HZ * 1e9).astype(np.int64)
    truth = Trajectory(stamps_ns=stamps, positions_xyz=truth_xyz, name="mocap")
    estimate = Trajectory(
        stamps_ns=stamps, positions_xyz=truth_xyz + error[:, None] * direction, name="slam"
    )
    return truth, estimate, error


def evaluate_office() -> EvaluationResult:
    """Return the office run evaluated against 0.025 m @ 95 %, no alignment (ATE = the error)."""
    truth, estimate, _ = office_run()
    config = EvaluationConfig(align=AlignMethod.NONE, tolerance=Tolerance(TOLERANCE_M, 0.95))
    return evaluate(truth, [estimate], config)


def room_of(x: float, y: float) -> str | None:
    """Return the room ``"2.14 Office"`` the point lies in, from the plan's numbers, or None."""
    for (number, name), (x0, x1, y0, y1) in OFFICE_ROOMS.items():
        if x0 <= x <= x1 and y0 <= y <= y1:
            return f"{number} {name}"
    return None
