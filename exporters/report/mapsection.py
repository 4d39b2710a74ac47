"""The report's map section: the robot's map against the building plan, formatted.

Built only when a map was measured (``result.map`` is set); its figure (the map's wall
cells on the plan, coloured by distance) is drawn by :mod:`exporters.plots.mapplan` and
listed with the report's other plots.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from loceval.evaluation import EvaluationResult

if TYPE_CHECKING:
    # Only named here: importing loceval.maps loads scipy.spatial, which a report of a
    # run without a map never needs.
    from loceval.maps import MapSnapshot, WallFigures
    from loceval.maps.axis_scale import AxisScales

__all__ = ["MapView", "build_map_view"]


@dataclass(frozen=True, slots=True)
class MapView:
    """The map section, formatted.

    Attributes:
        source: the map's file or topic.
        placed_by: how the map was placed ("SLAM's alignment").
        wall_cells: wall cells measured, and the clutter left out, in words.
        drift: the similarity scale in words ("the map is 1.2 % short").
        thresholds: the share-within thresholds as column heads.
        rows: placed, rigid fit, similarity fit: RMSE, mean, median, p95, max, within
            shares, coverage and the fit's transform.
        regions: the worst regions (tile centre, cells, RMSE).
        warnings: the map evaluation's warnings.
        history: a bag topic's messages, one row each: time, size, wall cells, RMSE as
            placed and after each fit, the similarity scale error, the rigid fit's
            rotation, coverage, or why the message was not judged.
        history_note: how the messages were chosen, when not all were judged.
        axis_scales: the per-axis lengths in words, or None when unobservable.
    """

    source: str
    placed_by: str
    wall_cells: str
    drift: str
    thresholds: tuple[str, ...]
    rows: tuple[Mapping[str, object], ...]
    regions: tuple[str, ...]
    warnings: tuple[str, ...]
    history: tuple[Mapping[str, str], ...] = ()
    history_note: str | None = None
    axis_scales: str | None = None


def _row(name: str, figures: WallFigures, transform: str) -> dict[str, object]:
    coverage = figures.plan_coverage
    return {
        "name": name,
        "rmse": f"{figures.rmse:.3f}",
        "mean": f"{figures.mean:.3f}",
        "median": f"{figures.median:.3f}",
        "p95": f"{figures.p95:.3f}",
        "max": f"{figures.max:.3f}",
        "within": [f"{share * 100:.1f} %" for share in figures.within.values()],
        "coverage": "–" if coverage is None else f"{coverage * 100:.1f} %",
        "transform": transform,
    }


def build_map_view(result: EvaluationResult) -> MapView | None:
    """Return the map section of the report, or None when no map was measured."""
    found = result.map
    if found is None:
        return None
    rows = [_row("as placed", found.placed, "—")]
    for name, (fit, figures) in (("rigid fit", found.rigid), ("similarity fit", found.similarity)):
        d = fit.to_dict()
        tx, ty = fit.translation_m
        text = f"scale {d['scale']:.4f}, {d['rotation_deg']:+.2f}°, ({tx:+.3f}, {ty:+.3f}) m"
        rows.append(_row(name, figures, text))
    worst = sorted(found.regions, key=lambda r: -float(r["rmse_m"]))[:5]
    regions = tuple(
        f"({r['x_m']:g}, {r['y_m']:g}) m: {float(r['rmse_m']):.3f} m over {r['n']} cells"
        for r in worst
    )
    n = len(found.cells_xy)
    return MapView(
        source=found.source,
        placed_by=f"{found.estimate}'s alignment" if found.estimate else "the given transform",
        wall_cells=(
            f"{n - found.clutter_cells:,} wall cells measured; {found.clutter_cells:,} farther "
            f"than {found.clutter_m:g} m from every plan wall after the fit are clutter (not in "
            "the plan) and left out"
        ),
        drift=found.drift_sentence(),
        thresholds=tuple(f"≤ {t:g} m" for t in found.placed.within),
        rows=tuple(rows),
        regions=regions,
        warnings=found.warnings,
        history=tuple(_history_row(s) for s in found.history),
        history_note=found.history_note,
        axis_scales=_axis_sentence(found.axis_scales),
    )


def _axis_sentence(scales: AxisScales | None) -> str | None:
    """``"along its x axis (0° on the plan) 2.00 % long (± 0.001 %), along y 1.00 % short"``."""
    if scales is None:
        return None
    parts = []
    for axis, pct, scale, sigma in (
        ("x", scales.length_error_x_pct, scales.scale_x, scales.sigma_x),
        ("y", scales.length_error_y_pct, scales.scale_y, scales.sigma_y),
    ):
        if pct is None or scale is None:
            parts.append(f"along {axis} not observable")
            continue
        spread = "" if sigma is None else f" (± {100.0 * sigma / scale**2:.3f} %)"
        parts.append(f"along {axis} {abs(pct):.2f} % {'short' if pct < 0 else 'long'}{spread}")
    axes = round(scales.axes_deg, 1) + 0.0  # never "-0.0"
    return f"per axis of the map (its x axis at {axes:.1f}° on the plan): " + ", ".join(parts)


def _number(value: float | None, spec: str) -> str:
    return "–" if value is None else format(value, spec)


def _history_row(snapshot: MapSnapshot) -> dict[str, str]:
    """One message of a map topic, formatted."""
    cols, rows = snapshot.size_cells
    return {
        "index": str(snapshot.index),
        "t": _number(snapshot.t_s, ".1f"),
        "size": f"{cols} x {rows}",
        "wall_cells": "–" if snapshot.wall_cells is None else f"{snapshot.wall_cells:,}",
        "placed": _number(snapshot.placed_rmse_m, ".3f"),
        "rigid": _number(snapshot.rigid_rmse_m, ".3f"),
        "similarity": _number(snapshot.similarity_rmse_m, ".3f"),
        "scale": _number(snapshot.scale_error_pct, "+.2f"),
        "rotation": _number(snapshot.rigid_rotation_deg, "+.2f"),
        "coverage": _number(
            None if snapshot.plan_coverage is None else snapshot.plan_coverage * 100, ".1f"
        ),
        "note": snapshot.note or "",
    }
