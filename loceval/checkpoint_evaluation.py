"""A whole evaluation against control points: one survey, one or more estimates.

:func:`evaluate_control_points` scores each estimate with
:func:`loceval.checkpoints.fit.evaluate_checkpoints` and returns a
:class:`CheckpointEvaluation`, whose :meth:`~CheckpointEvaluation.to_dict` is the
``--json`` document of a control-point reference: the same top-level keys as a trajectory
evaluation's (``loceval_version``, ``options``, ``inputs``, ``reference``, ``estimates``),
with ``reference.kind == "control_points"`` and the checkpoint entries per estimate.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from loceval._version import __version__
from loceval.calibration.clockmodel import ClockModel
from loceval.checkpoints.config import CheckpointConfig
from loceval.checkpoints.fit import CheckpointResult, evaluate_checkpoints
from loceval.controlpoints import ControlPoints, Visits
from loceval.evaluation import EvaluationConfig
from loceval.trajectory import Trajectory

__all__ = [
    "CheckpointConfig",
    "CheckpointEstimate",
    "CheckpointEvaluation",
    "errors_table",
    "evaluate_control_points",
]

_NS_PER_S = 1_000_000_000


@dataclass(frozen=True, slots=True, eq=False)
class CheckpointEstimate:
    """One estimate scored against the control points.

    Attributes:
        estimate: the estimate as read (time offset applied).
        result: its visits, errors and scores.
    """

    estimate: Trajectory
    result: CheckpointResult

    @property
    def name(self) -> str:
        """Return the estimate's name."""
        return self.estimate.name

    def to_dict(self) -> dict[str, object]:
        """Return the estimate entry of the result document."""
        est = self.estimate
        return {
            "name": est.name,
            "source": est.source,
            "poses": len(est),
            "duration_s": est.duration_s,
            **self.result.to_dict(),
            "warnings": [*est.warnings, *self.result.warnings],
        }


@dataclass(frozen=True, slots=True, eq=False)
class CheckpointEvaluation:
    """A whole evaluation against control points, and how it was made.

    Attributes:
        points: the control points.
        reference_name: the reference's name.
        estimates: one entry per estimate.
        config: the evaluation options (alignment, thresholds, time offset).
        checkpoints: the control-point options.
        visits_source: ``auto`` or the visits file's name.
        created_at: ISO time of the evaluation (UTC).
        loceval_version: the version that made it.
        inputs: the provenance of each input (reference first).
    """

    points: ControlPoints
    reference_name: str
    estimates: tuple[CheckpointEstimate, ...]
    config: EvaluationConfig
    checkpoints: CheckpointConfig
    visits_source: str
    created_at: str
    loceval_version: str = __version__
    inputs: tuple[Mapping[str, object], ...] = ()

    def to_dict(self) -> dict[str, object]:
        """Return the CLI's ``--json`` document (also the service's result schema)."""
        points = self.points
        extent = points.positions_xyz.max(axis=0) - points.positions_xyz.min(axis=0)
        return {
            "loceval_version": self.loceval_version,
            "created_at": self.created_at,
            "options": {
                "align": self.config.align.value,
                "time_offset_s": self.config.time_offset_s,
                "thresholds_m": list(self.config.thresholds_m),
                "visits": self.visits_source,
                **self.checkpoints.to_dict(),
            },
            "inputs": [dict(i) for i in self.inputs],
            "reference": {
                "name": self.reference_name,
                "source": points.source,
                "kind": "control_points",
                "points": len(points),
                "ids": list(points.ids),
                "extent_m": [float(e) for e in extent],
                "min_spacing_m": points.min_spacing_m(),
                "sigma_given": points.sigma_xyz is not None,
                "warnings": list(points.warnings),
            },
            "estimates": [e.to_dict() for e in self.estimates],
        }


def evaluate_control_points(
    points: ControlPoints,
    estimates: Sequence[Trajectory],
    config: EvaluationConfig,
    checkpoints: CheckpointConfig,
    *,
    visits: Visits | None = None,
    reference_name: str = "",
    inputs: Sequence[Mapping[str, object]] = (),
    progress: Callable[[str, float], None] | None = None,
) -> CheckpointEvaluation:
    """Score every estimate against the control points.

    Args:
        points: the surveyed control points.
        estimates: the systems under test.
        config: the alignment method, thresholds and time offset are used.
        checkpoints: the visit radius, alignment points and stop detection.
        visits: when the device stood on which point (a visits file); None finds the
            stops of each estimate.
        reference_name: the reference's name in the result.
        inputs: the provenance of each input (reference first).
        progress: called with (stage, fraction done).

    Returns:
        The evaluation.

    Raises:
        InputError: see :func:`loceval.checkpoints.fit.evaluate_checkpoints`.
        AlignmentError: the alignment is undetermined or ambiguous.
    """
    report = progress or (lambda _stage, _fraction: None)
    offset_ns = round(config.time_offset_s * _NS_PER_S)
    entries = []
    for k, estimate in enumerate(estimates):  # one iteration per estimate
        report(f"scoring {estimate.name}", k / max(len(estimates), 1))
        shifted = estimate.shifted(offset_ns) if offset_ns else estimate
        if config.clock_drift_ppm:  # a given clock rate, from the estimate's first stamp
            epoch_ns = int(shifted.stamps_ns[0])
            shifted = ClockModel(0.0, epoch_ns, rate_ppm=config.clock_drift_ppm).restamped(shifted)
        result = evaluate_checkpoints(
            points,
            shifted,
            visits=visits,
            method=config.align,
            align_points=checkpoints.align_points,
            visit_radius_m=checkpoints.visit_radius_m,
            stop_max_speed_mps=checkpoints.stop_speed_mps,
            stop_min_duration_s=checkpoints.stop_min_s,
            thresholds_m=config.thresholds_m,
        )
        entries.append(CheckpointEstimate(shifted, result))
    report("scored", 1.0)
    return CheckpointEvaluation(
        points=points,
        reference_name=reference_name or points.source,
        estimates=tuple(entries),
        config=config,
        checkpoints=checkpoints,
        visits_source=visits.source if visits is not None else "auto",
        created_at=dt.datetime.now(tz=dt.UTC).isoformat(timespec="seconds"),
        inputs=tuple(inputs),
    )


def errors_table(evaluation: CheckpointEvaluation) -> tuple[list[str], list[list[object]]]:
    """Return the header and rows of ``errors.csv``: one row per visit of every estimate."""
    header = [
        "estimate",
        "id",
        "t_start_s",
        "t_end_s",
        "samples",
        "spread_m",
        "x_m",
        "y_m",
        "z_m",
        "surveyed_x_m",
        "surveyed_y_m",
        "surveyed_z_m",
        "error_m",
        "error_h_m",
        "error_v_m",
        "used_for_alignment",
    ]
    rows: list[list[object]] = []
    for entry in evaluation.estimates:
        for v in entry.result.visits:  # one row per visit (tens to hundreds)
            error = v.error_xyz
            rows.append(
                [
                    entry.name,
                    v.point_id,
                    v.start_ns / _NS_PER_S,
                    v.end_ns / _NS_PER_S,
                    v.samples,
                    v.spread_m,
                    *v.measured_xyz,
                    *v.surveyed_xyz,
                    float(np.linalg.norm(error)),
                    float(np.hypot(error[0], error[1])),
                    float(error[2]),
                    v.used_for_alignment,
                ]
            )
    return header, rows
