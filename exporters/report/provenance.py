"""The report's provenance tables: input files, trajectories, options and the alignment.

Split from :mod:`exporters.report.view`, which assembles them into the report's view.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from exporters.plots import (
    REFERENCE_COLOUR,
    describe_rpe_step,
    estimate_colour,
)
from exporters.report.clocks import clock_drift_text, time_offset_text
from loceval.core.arrays import FloatArray
from loceval.core.gaps import GAP_RATE_FACTOR
from loceval.core.lengths import format_coordinate
from loceval.evaluation import EstimateResult, EvaluationResult
from loceval.registration.alignment import AlignWindow
from loceval.trajectory import Trajectory

__all__ = [
    "alignment_rows",
    "estimate_name",
    "format_xyz",
    "input_rows",
    "option_rows",
    "trajectory_rows",
    "yaw_pitch_roll_deg",
]


_GIMBAL_LOCK: float = 1.0 - 1e-12
"""``|sin(pitch)|`` beyond which yaw and roll turn about the same axis (pitch ±90°)."""


def yaw_pitch_roll_deg(rotation: FloatArray) -> tuple[float, float, float]:
    """Return the intrinsic z-y'-x'' angles of a rotation matrix, degrees.

    ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (the order of scipy's ``as_euler("ZYX")``):
    yaw and roll in (-180°, 180°], pitch in [-90°, 90°]. At pitch ±90° (gimbal lock)
    only yaw ∓ roll is defined; roll is then 0 and yaw carries the whole turn.

    Args:
        rotation: (3, 3) rotation matrix.
    """
    r = np.asarray(rotation, dtype=np.float64)
    sin_pitch = float(np.clip(-r[2, 0], -1.0, 1.0))
    pitch = math.atan2(sin_pitch, math.hypot(r[0, 0], r[1, 0]))  # exact near ±90°
    if abs(sin_pitch) >= _GIMBAL_LOCK:
        yaw, roll = math.atan2(-r[0, 1], r[1, 1]), 0.0
    else:
        yaw, roll = math.atan2(r[1, 0], r[0, 0]), math.atan2(r[2, 1], r[2, 2])
    return math.degrees(yaw), math.degrees(pitch), math.degrees(roll)


def estimate_name(e: EstimateResult, k: int) -> str:
    """Return an estimate's name, or its number when it has none."""
    return e.name or f"estimate {k + 1}"


def format_xyz(position: Iterable[float]) -> str:
    """Return a position in metres as the report writes it, to the mm: ``1.234, 4.560, 0.100``.

    The one rule for coordinates (:func:`loceval.core.lengths.format_coordinate`).
    """
    return ", ".join(format_coordinate(v, per_metre=1.0) for v in position)


def _size(value: object) -> str:
    """A byte count for people: ``123.5 kB``, ``987.7 MB``."""
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        return ""
    units = ("B", "kB", "MB", "GB", "TB")
    k = 0 if value < 1000 else min(int(math.log10(value)) // 3, len(units) - 1)
    return f"{value:,} B" if k == 0 else f"{value / 1000**k:,.1f} {units[k]}"


def _text(value: object) -> str:
    return "" if value is None else str(value)


def input_rows(result: EvaluationResult) -> tuple[Mapping[str, str], ...]:
    """Return the input files: role, file, format, selector, size and SHA-256."""
    rows = []
    for info in result.inputs:
        path = _text(info.get("path"))
        rows.append(
            {
                "role": _text(info.get("role")),
                "file": _text(info.get("file")) or (Path(path).name if path else ""),
                "path": path,
                "format": _text(info.get("format")),
                "selector": _text(info.get("selector")),
                "sha256": _text(info.get("sha256")),
                "size": _size(info.get("bytes")),
            }
        )
    return tuple(rows)


def _duration(trajectory: Trajectory) -> str:
    """The time a trajectory spans, or that it has no times (poses numbered, no stamps)."""
    return trajectory.span_words


def trajectory_rows(result: EvaluationResult) -> tuple[Mapping[str, str], ...]:
    """Return the trajectories as read: poses, duration, length and rate."""
    ref = result.reference
    rows: list[Mapping[str, str]] = [
        {
            "role": "reference",
            "name": ref.name or "reference",
            "colour": REFERENCE_COLOUR,
            "source": ref.source,
            "poses": f"{len(ref):,}",
            "matched": "",
            "duration": _duration(ref),
            "length": f"{ref.length_m:.1f} m",
            "rate": "—" if ref.indexed else f"{ref.rate_hz:.1f} Hz",
            "orientation": "yes" if ref.has_orientation else "no",
        }
    ]
    for k, e in enumerate(result.estimates):
        est = e.estimate
        rows.append(
            {
                "role": "estimate",
                "name": estimate_name(e, k),
                "colour": estimate_colour(k),
                "source": est.source,
                "poses": f"{len(est):,}",
                "matched": f"{len(e.association):,}",
                "duration": _duration(est),
                "length": f"{est.length_m:.1f} m",
                "rate": "—" if est.indexed else f"{est.rate_hz:.1f} Hz",
                "orientation": "yes" if est.has_orientation else "no",
            }
        )
    return tuple(rows)


def option_rows(result: EvaluationResult) -> tuple[tuple[str, str], ...]:
    """Return the evaluation's options in words."""
    cfg = result.config
    gaps = (
        f"tracking loss: an interval longer than {cfg.max_gap_s:g} s and than "
        f"{GAP_RATE_FACTOR} of the source's median intervals"
    )
    association = (
        f"interpolate the reference at the estimate's stamps ({gaps}, never bridged)"
        if cfg.association.value == "interpolate"
        else f"nearest reference pose within {cfg.max_dt_s:g} s ({gaps})"
    )
    rows = [
        ("Association", association),
        ("Time offset", time_offset_text(cfg)),
        ("Clock drift", clock_drift_text(cfg)),
        (
            "Alignment",
            "none (the estimates are compared in the reference's frame as they are)"
            if cfg.align.value == "none"
            else f"{cfg.align.value} (estimated on {_window(cfg.align_first)})",
        ),
        (
            "RPE step",
            describe_rpe_step(result.config)
            + (", every pose starts a pair" if cfg.rpe_all_pairs else ", consecutive steps"),
        ),
        ("Thresholds", ", ".join(f"{t:g} m" for t in cfg.thresholds_m)),
        ("Tolerance", "none given" if cfg.tolerance is None else str(cfg.tolerance)),
    ]
    if cfg.align.value == "calibrate":
        at = "the first matched pose" if cfg.calibrate_at_s is None else f"{cfg.calibrate_at_s:g} s"
        rows.insert(3, ("Calibration pose", at))
    if cfg.reference_offset is not None:
        t = cfg.reference_offset.translation
        rows.append(("Device offset", f"{format_xyz(t)} m (rigid body → sensor)"))
    return tuple(rows)


def _window(window: AlignWindow) -> str:
    """Return the alignment window in words: ``all poses``, ``the first 5 s``."""
    if window.poses is not None:
        return "the first pose" if window.poses == 1 else f"the first {window.poses:,} poses"
    if window.seconds is not None:
        return f"the first {window.seconds:g} s"
    return "all poses"


def alignment_rows(result: EvaluationResult) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """The transform found per estimate, rows down and estimates across (as Tables 1-2)."""
    labels = (
        "method",
        "poses used",
        "translation [m]",
        "rotation (yaw, pitch, roll)",
        "scale",
        "matrix [sR | t]",
    )
    columns: list[tuple[str, ...]] = []
    for e in result.estimates:
        a = e.alignment
        tf = a.transform
        yaw, pitch, roll = yaw_pitch_roll_deg(tf.rotation)
        matrix = np.hstack([tf.scale * tf.rotation, tf.translation[:, None]])
        columns.append(
            (
                a.method.value,
                "none (no alignment)"
                if a.method.value == "none"
                else f"{a.poses_used:,} (window: {a.window})",
                format_xyz(tf.translation),
                f"{yaw:.2f}°, {pitch:.2f}°, {roll:.2f}°",
                f"{tf.scale:.6f}",
                "\n".join(" ".join(f"{v:+.4f}" for v in row) for row in matrix),
            )
        )
    return tuple((label, tuple(col[r] for col in columns)) for r, label in enumerate(labels))
