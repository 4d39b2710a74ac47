"""The terminal tables of ``loceval evaluate``: the framework paper's Tables 1-2 layout."""

from __future__ import annotations

from collections.abc import Sequence

from loceval.evaluation import EvaluationResult
from loceval.metrics import ErrorSeries, ErrorStats, RPEUnit

__all__ = ["format_tables"]

_ROWS = (("RMSE", "rmse"), ("MEAN", "mean"), ("MEDIAN", "median"), ("STD", "std"),
         ("MIN", "min"), ("MAX", "max"))  # fmt: skip


def format_tables(result: EvaluationResult) -> str:
    """Return the framework paper's Tables 1-2 layout: one column per estimate."""
    ref = result.reference
    head = f"Reference {ref.name!r}: {len(ref)} poses, {ref.duration_s:.1f} s, "
    lines = [head + f"{ref.length_m:.1f} m ({ref.source})"]
    for e in result.estimates:
        scale = e.alignment.transform
        lines.append(
            f"  {e.name}: {len(e.association)} of {len(e.estimate)} poses matched, "
            f"aligned {e.alignment.method.value}"
            + ("" if scale.is_rigid else f" (scale {scale.scale:.4f})")
        )
    for title, stats, unit in _sections(result):
        lines += ["", title, _row("error metric", [e.name for e in result.estimates])]
        for label, key in _ROWS:
            cells = ["-" if s is None else f"{getattr(s, key):.3f} {unit}" for s in stats]
            lines.append(_row(label, cells))
    lines += ["", "Share of poses within (ATE)"]
    for t in result.config.thresholds_m:
        shares = [f"{e.within[t] * 100:.1f} %" for e in result.estimates]
        lines.append(_row(f"<= {t:g} m", shares))
    drifts = [_stats(e.drift) for e in result.estimates]
    if any(d is not None for d in drifts):
        cells = ["-" if d is None else f"{d.mean:.2f} %" for d in drifts]
        lines.append(_row("drift (mean)", cells))
    lines += [f"\n{e.name}: {e.verdict.summary}" for e in result.estimates if e.verdict]
    if result.comparisons:
        lines += [
            "",
            "Comparisons (95 % intervals)",
            *(f"  {c.summary}" for c in result.comparisons),
        ]
    warnings = [("reference", w) for w in result.reference_warnings] + [
        (e.name, w) for e in result.estimates for w in e.warnings
    ]
    if warnings:
        lines += ["", "Warnings", *(f"  {who}: {w}" for who, w in warnings)]
    return "\n".join(lines)


def _sections(result: EvaluationResult) -> list[tuple[str, list[ErrorStats | None], str]]:
    est = result.estimates
    cfg = result.config
    sections: list[tuple[str, list[ErrorStats | None], str]] = [
        ("Absolute Trajectory Error (ATE)", [e.ate_translation.stats for e in est], "m")
    ]
    if any(e.ate_rotation is not None for e in est):
        sections.append(("ATE rotation", [_stats(e.ate_rotation) for e in est], "deg"))
    unit = cfg.rpe_unit.value
    if cfg.rpe_unit is RPEUnit.FRAMES and cfg.rpe_delta == 1:
        unit = "frame"
    rpe_title = f"Relative Pose Error (RPE, delta {cfg.rpe_delta:g} {unit})"
    sections.append((rpe_title, [e.rpe_translation.stats for e in est], "m"))
    if any(e.rpe_rotation is not None for e in est):
        sections.append(("RPE rotation", [_stats(e.rpe_rotation) for e in est], "deg"))
    return sections


def _stats(series: ErrorSeries | None) -> ErrorStats | None:
    return None if series is None else series.stats


def _row(label: str, cells: Sequence[str]) -> str:
    return f"{label:<14}" + "".join(f"{c:>16}" for c in cells)
