"""The terminal tables of ``loceval evaluate``: the framework paper's Tables 1-2 layout."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

from loceval.checkpoint_evaluation import CheckpointEvaluation
from loceval.core.lengths import LengthUnit, length_unit
from loceval.core.quantities import ARROW, AT_MOST, format_duration
from loceval.evaluation import EvaluationResult
from loceval.metrics.pose_errors import ErrorSeries, ErrorStats, RPEUnit
from service.cli.trials import trial_lines

__all__ = ["format_checkpoint_tables", "format_tables"]

_ROWS = (("RMSE", "rmse"), ("MEAN", "mean"), ("MEDIAN", "median"), ("STD", "std"),
         ("MIN", "min"), ("MAX", "max"))  # fmt: skip


def format_tables(result: EvaluationResult) -> str:
    """Return the framework paper's Tables 1-2 layout: one column per estimate."""
    ref = result.reference
    head = f"Reference {ref.name!r}: {len(ref)} poses, {ref.span_words}, "
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
        # a table of lengths reads in one unit: mm when all its values are below 0.1 m
        length = None if unit != "m" else length_unit(_values(stats))

        def cell(value: float, unit: str = unit, length: LengthUnit | None = length) -> str:
            return f"{value:.3f} {unit}" if length is None else length.text(value)

        for label, key in _ROWS:
            cells = ["-" if s is None else cell(getattr(s, key)) for s in stats]
            lines.append(_row(label, cells))
    lines += ["", "Share of poses within (ATE)"]
    for t in result.config.thresholds_m:
        shares = [f"{e.within[t] * 100:.1f} %" for e in result.estimates]
        lines.append(_row(f"{AT_MOST} {t:g} m", shares))
    drifts = [_stats(e.drift) for e in result.estimates]
    if any(d is not None for d in drifts):
        cells = ["-" if d is None else f"{d.mean:.2f} %" for d in drifts]
        lines.append(_row("drift (mean)", cells))
    lines += _verdict_lines(result)
    lines += _excursion_lines(result)
    lines += _map_lines(result)
    lines += _block(
        "Comparisons (95 % intervals)", [("", c.summary) for c in result.comparisons or ()]
    )
    lines += trial_lines(result)
    lines += _block(
        "Inputs",
        [("reference", n) for n in result.reference.notes]
        + [(e.name, n) for e in result.estimates for n in e.estimate.notes],
    )
    lines += _block("Notes", [(e.name, n) for e in result.estimates for n in e.notes])
    warnings = [
        *(("reference", w) for w in result.reference_warnings),
        *((e.name, w) for e in result.estimates for w in e.warnings),
        *(("comparison", w) for w in result.comparison_notes),
        *(("building model", w) for w in (result.building.warnings if result.building else ())),
    ]
    lines += _block("Warnings", warnings)
    return "\n".join(lines)


def _block(title: str, items: Sequence[tuple[str, str]]) -> list[str]:
    """Return a titled block of ``who: text`` lines (``text`` alone without a who), or none."""
    if not items:
        return []
    return ["", title, *(f"  {who}: {text}" if who else f"  {text}" for who, text in items)]


def format_checkpoint_tables(result: CheckpointEvaluation) -> str:
    """Return the control-point figures: one column per estimate, then the visits."""
    points = result.points
    lines = [f"Reference {result.reference_name!r}: {len(points)} control points ({points.source})"]
    est = result.estimates
    for e in est:
        r = e.result
        lines.append(
            f"  {e.name}: {len(r.scored)} visits scored, {len(r.visits) - len(r.scored)} "
            f"fixed the alignment ({r.method.value}), {len(r.unvisited)} points unvisited, "
            f"{len(r.unmatched_stops)} stops matched no point"
        )
    lines += ["", "Error at the control points (3D)", _row("error metric", [e.name for e in est])]
    stats = [e.result.stats for e in est]
    for label, key in _ROWS:
        lines.append(_row(label, [f"{getattr(s, key):.3f} m" for s in stats]))
    documents = [e.result.to_dict() for e in est]
    scores = [cast("dict[str, Any]", d["checkpoints"]) for d in documents]
    lines += ["", "Scores"]
    lines.append(_row("Hilti", [f"{c['score']['hilti']:.1f}" for c in scores]))
    lines.append(_row("LaMAria", [f"{c['score']['lamaria']:.1f}" for c in scores]))
    for t in result.config.thresholds_m:
        key = f"{t:g}"
        lines.append(_row(f"recall {key} m", [f"{c['recall'][key] * 100:.1f} %" for c in scores]))
    for e in est:
        head = f"  {'id':<10}{'t_start_s':>14}{'error_m':>10}{'error_h_m':>10}{'error_v_m':>10}"
        lines += ["", f"{e.name}: visits", head]
        lines.extend(
            f"  {v.point_id:<10}{v.start_ns / 1e9:>14.3f}{v.error_m:>10.3f}{v.error_h_m:>10.3f}"
            f"{v.error_v_m:>+10.3f}{'  (alignment)' if v.used_for_alignment else ''}"
            for v in e.result.visits
        )
        if e.result.unvisited:
            lines.append(f"  unvisited: {', '.join(e.result.unvisited)}")
    warnings = [(e.name, w) for e in est for w in (*e.estimate.warnings, *e.result.warnings)]
    if warnings:
        lines += ["", "Warnings", *(f"  {who}: {w}" for who, w in warnings)]
    return "\n".join(lines)


_STRETCHES_LISTED = 5  # as the report's verdict lists them


def _values(stats: Sequence[ErrorStats | None]) -> list[float]:
    return [getattr(s, key) for s in stats if s is not None for _, key in _ROWS]


def _verdict_lines(result: EvaluationResult) -> list[str]:
    """Each verdict, then its worst stretches beyond the tolerance, with their rooms."""
    lines: list[str] = []
    for e in result.estimates:
        verdict = e.verdict
        if verdict is None:
            continue
        lines += ["", f"{e.name}: {verdict.summary}"]
        spans = verdict.failing_spans
        unit = length_unit(s.max_error_m for s in spans[:_STRETCHES_LISTED])
        lines.extend(
            f"  #{k} {s.words(verdict.tolerance.distance_m)}: from t = {s.start_s:.1f} s, "
            f"{s.length_m:.1f} m travelled, worst {unit.text(s.max_error_m)}"
            for k, s in enumerate(spans[:_STRETCHES_LISTED], start=1)
        )
        if len(spans) > _STRETCHES_LISTED:
            lines.append(f"  ... {len(spans) - _STRETCHES_LISTED} more (result.json lists all)")
    return lines


def _excursion_lines(result: EvaluationResult) -> list[str]:
    """One line per excursion, its drift per metre travelled outside as a percentage.

    ``"out of the room for 45.0 s over 45.0 m: error 0.000 m on leaving → 0.225 m at
    re-entry, drift 0.50 % of the distance travelled outside"``: the percentage is the
    error's change over the excursion's own path (issue 44 read "0.06 % of the path" as a
    share of the whole run's path).
    """
    lines = []
    for e in result.estimates:
        for x in e.excursions:  # a few per run
            before = "-" if x.error_before_m is None else f"{x.error_before_m:.3f} m"
            after = "-" if x.error_after_m is None else f"{x.error_after_m:.3f} m"
            drift = (
                ""
                if x.drift_per_m is None
                else f", drift {x.drift_per_m * 100:.2f} % of the distance travelled outside"
            )
            lines.append(
                f"{e.name}: out of the room for {format_duration((x.end_ns - x.start_ns) / 1e9)} "
                f"over {x.path_length_m:.1f} m: error {before} on leaving {ARROW} {after} at "
                f"re-entry{drift}"
            )
    return ["", "Excursions", *(f"  {line}" for line in lines)] if lines else []


def _map_lines(result: EvaluationResult) -> list[str]:
    """The map against the plan: wall distances as placed and after the fits."""
    found = result.map
    if found is None:
        return []
    lines = ["", f"Map against the plan ({found.source}, {found.clutter_cells} clutter cells)"]
    rows = (("as placed", found.placed), ("rigid fit", found.rigid[1]))
    for label, figures in (*rows, ("similarity fit", found.similarity[1])):
        coverage = "-" if figures.plan_coverage is None else f"{figures.plan_coverage:.1%}"
        lines.append(
            f"  {label:<15} RMSE {figures.rmse:.3f} m, p95 {figures.p95:.3f} m, "
            f"max {figures.max:.3f} m, coverage {coverage}"
        )
    lines.append(f"  {found.drift_sentence()}")
    return lines


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
