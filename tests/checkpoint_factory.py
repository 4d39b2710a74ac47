"""Synthetic stop-and-go recordings over surveyed control points, with known truth."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from loceval.controlpoints import ControlPoints
from loceval.trajectory import Trajectory

if TYPE_CHECKING:
    from loceval.checkpoint_evaluation import CheckpointEvaluation

NS = 1_000_000_000
T0_NS = 1_700_000_000 * NS  # epoch-scale stamps, as a real recording has


@dataclass(frozen=True)
class StopAndGo:
    """A recording and what is true about it."""

    points: ControlPoints
    estimate: Trajectory
    visit_ids: list[str]  # the point of each true visit, in time order
    visit_start_ns: np.ndarray
    visit_end_ns: np.ndarray


def grid_points(rows: int = 5, cols: int = 9, spacing_m: float = 0.3) -> ControlPoints:
    """Return a rows x cols floor grid (the reference-robot paper's 5 x 9 at 30 cm)."""
    yy, xx = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    xyz = np.stack([xx.ravel() * spacing_m, yy.ravel() * spacing_m, np.zeros(rows * cols)], 1)
    ids = tuple(f"P{r}{c}" for r in range(rows) for c in range(cols))
    return ControlPoints(ids, xyz, np.full((rows * cols, 3), 0.001), source="grid")


def stop_and_go(
    rng: np.random.Generator,
    points: ControlPoints,
    *,
    passes: int = 3,
    dwell_s: float = 3.0,
    speed_mps: float = 0.3,
    rate_hz: float = 30.0,
    noise_m: float = 0.003,
    bias_xyz: tuple[float, float, float] = (0.01, -0.02, 0.005),
    frame: tuple[np.ndarray, np.ndarray] | None = None,
    order: list[int] | None = None,
) -> StopAndGo:
    """Visit every point ``passes`` times (a new random order each pass), stopping on each.

    The estimate is the true path plus ``bias_xyz``, Gaussian noise of ``noise_m`` per axis
    and, with ``frame`` = (R, t), expressed in another frame (true = R @ est + t).
    """
    n = len(points)
    sequence = order if order is not None else []
    if order is None:
        for _ in range(passes):
            sequence.extend(rng.permutation(n).tolist())
    knots_t, knots_p = [0.0], [points.positions_xyz[sequence[0]] - [0.5, 0.5, 0.0]]
    starts, ends = [], []
    for k in sequence:  # one leg per visit: drive there, then stand still
        target = points.positions_xyz[k]
        leg = float(np.linalg.norm(target - knots_p[-1]))
        arrive = knots_t[-1] + max(leg / speed_mps, 0.5)
        knots_t += [arrive, arrive + dwell_s]
        knots_p += [target, target]
        starts.append(arrive)
        ends.append(arrive + dwell_s)
    knots_t.append(knots_t[-1] + 2.0)
    knots_p.append(knots_p[-1] + [0.5, 0.0, 0.0])
    kt, kp = np.array(knots_t), np.array(knots_p)
    t = np.arange(0.0, kt[-1], 1.0 / rate_hz)
    truth = np.stack([np.interp(t, kt, kp[:, a]) for a in range(3)], axis=1)
    measured = truth + np.asarray(bias_xyz) + rng.normal(0.0, noise_m, truth.shape)
    if frame is not None:
        R, shift = frame
        measured = (measured - shift) @ R  # est = R^T (true - t)
    stamps = T0_NS + np.rint(t * NS).astype(np.int64)
    estimate = Trajectory(stamps, measured, None, name="est")
    to_ns = lambda s: T0_NS + np.rint(np.asarray(s) * NS).astype(np.int64)  # noqa: E731
    return StopAndGo(
        points=points,
        estimate=estimate,
        visit_ids=[points.ids[k] for k in sequence],
        visit_start_ns=to_ns(starts),
        visit_end_ns=to_ns(ends),
    )


def estimate_tum_rows(recording: StopAndGo) -> list[str]:
    """The estimate's positions as position-only TUM rows ``t x y z`` (t in seconds)."""
    estimate = recording.estimate
    return [
        f"{t / NS:.9f} {x!r} {y!r} {z!r}"
        for t, (x, y, z) in zip(estimate.stamps_ns, estimate.positions_xyz.tolist(), strict=True)
    ]


def write_points(path: Path, points: ControlPoints, *, header: str = "id,x,y,z,sigma_m") -> Path:
    """Write a survey CSV."""
    rows = [header]
    for pid, (x, y, z), s in zip(points.ids, points.positions_xyz, points.sigma_xyz, strict=True):
        rows.append(f"{pid},{float(x)!r},{float(y)!r},{float(z)!r},{float(s[0])!r}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def write_visits(path: Path, recording: StopAndGo) -> Path:
    """Write the true visits as a visits CSV (seconds)."""
    rows = ["id,t_start,t_end"]
    for pid, a, b in zip(
        recording.visit_ids, recording.visit_start_ns, recording.visit_end_ns, strict=True
    ):
        rows.append(f"{pid},{a / NS:.6f},{b / NS:.6f}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def survey_evaluation(rng: np.random.Generator) -> CheckpointEvaluation:
    """A 3 x 4 grid at 30 cm visited twice, scored without alignment (the reports' example)."""
    from loceval.checkpoint_evaluation import CheckpointConfig, evaluate_control_points
    from loceval.evaluation import EvaluationConfig
    from loceval.registration.alignment import AlignMethod

    recording = stop_and_go(rng, grid_points(3, 4), passes=2)
    return evaluate_control_points(
        recording.points,
        [recording.estimate],
        EvaluationConfig(align=AlignMethod.NONE),
        CheckpointConfig(),
        reference_name="survey",
    )
