"""What the viewer draws, as one JSON-ready document: paths, errors, building, anchors.

Everything is in the site frame and units the CAD files use (:mod:`exporters.cad.placement`):
the evaluation frame mapped by the site transform (an IFC building's own map conversion
when no site is given), scaled to the output units. Vertices are sent relative to the
same base point as the GLB (the reference's bounding-box centre rounded to whole metres),
so a national-grid site keeps its precision in the browser's 32-bit vertex buffers; the
read-outs add it back.

Per path the document holds its display set (:func:`~exporters.viewer.reduce.display_indices`):
stamps in seconds since the reference's first stamp (as the report and ``errors.csv``),
local vertices, the display indices after which a piece ends (a tracking loss of the path
or of the reference, :func:`loceval.core.gaps.path_breaks`: drawn as a break, never a chord)
and, for an estimate, its ATE at each vertex (rounded as in ``errors.csv``) with the
reference position that error is measured to. ``excursions`` lists each stretch an
estimate spent outside the tracked room (:mod:`exporters.cad.excursions`, the CAD files'
selection): its path (every pose inside it), label and figures.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Final

import numpy as np

from exporters.cad.building import (
    FRAME_BUILDING_UP_TO,
    BuildingModel,
    georeferenced_options,
    read_underlay,
)
from exporters.cad.excursions import EXCURSION_RGB, excursion_paths
from exporters.cad.site import check_options
from exporters.cad.spaces import placed_on_building
from exporters.colours import (
    ATEBin,
    error_bins,
    error_unit,
    hex_colour,
    palette_color,
    scale_words,
)
from exporters.options import ExportOptions, Units
from exporters.tables import ERROR_DECIMALS
from exporters.viewer.reduce import display_indices
from loceval import __version__
from loceval.core.arrays import BoolArray, FloatArray, IntArray
from loceval.core.display import display_text
from loceval.core.gaps import path_breaks
from loceval.core.geometry import SimilarityTransform
from loceval.core.lengths import LengthUnit, coordinate_decimals
from loceval.evaluation import EstimateResult, EvaluationResult
from loceval.metrics.pose_errors import WorstPose
from loceval.trajectory import Trajectory

__all__ = [
    "bins_json",
    "building_scene",
    "flat_rounded",
    "vertex_decimals",
    "viewer_scene",
]

_NS_PER_S: Final = 1_000_000_000
MAX_STRETCHES: Final = 500
"""Stretches beyond the tolerance the viewer lists and keeps in its display set, the worst
first (a noisy run hovering at the tolerance has tens of thousands; result.json has all)."""
_TIME_DECIMALS: Final = 6  # microseconds: finer than any recording's stamps need here
_RESOLUTION_M: Final = 1e-4  # vertices are rounded to 0.1 mm
_MAX_BUILDING_FACES: Final = 400_000
_MAX_ELLIPSES: Final = 400  # uncertainty ellipses per estimate: more only blur into a band
_SIGMAS: Final = 2.0  # the ellipses are 2-sigma (about 86 % of a 2D normal's mass)


def bins_json(bins: Sequence[ATEBin]) -> list[dict[str, object]]:
    """Return the ATE colour bins as the scene's legend (an open top bin has no ``high``)."""
    return [
        {
            "high": None if math.isinf(b.high_m) else b.high_m,
            "color": hex_colour(b.color_rgb),
            "label": b.label,
            "beyond": b.beyond,
        }
        for b in bins
    ]


def vertex_decimals(units: Units) -> int:
    """Decimals of a vertex coordinate in ``units`` that keep :data:`_RESOLUTION_M`."""
    return max(0, round(-math.log10(_RESOLUTION_M * units.per_metre)))


def flat_rounded(values: FloatArray, decimals: int) -> list[float]:
    """Return an array flattened to a list, rounded to ``decimals`` (compact JSON)."""
    out: list[float] = np.round(np.asarray(values, dtype=np.float64), decimals).ravel().tolist()
    return out


def _display_breaks(breaks: BoolArray, kept: IntArray) -> list[int]:
    """Display indices ``k`` after which a piece ends (a break between kept[k] and kept[k+1])."""
    if kept.shape[0] < 2:
        return []
    crossed = np.concatenate(([0], np.cumsum(breaks, dtype=np.int64)))
    out: list[int] = np.flatnonzero(crossed[kept[1:]] > crossed[kept[:-1]]).tolist()
    return out


def viewer_scene(result: EvaluationResult, options: ExportOptions) -> dict[str, object]:
    """Return the viewer's document of one evaluation (JSON-ready).

    Args:
        result: the evaluation.
        options: units, site transform, building model (mesh, IFC or DXF plan), title.

    Returns:
        The document ``viewer.js`` draws: ``paths`` (the reference first), ``bins`` (the
        ATE colour scale), ``worst`` (labels), ``anchors``, ``excursions``, ``building``
        and the frame.

    Raises:
        ExportOptionsError: bad units or site, or a building file that cannot be read.
    """
    check_options(options)
    result = placed_on_building(result, options)  # the stretches' spaces, the warnings
    options = georeferenced_options(options)
    units = Units(options.units)
    site = options.site
    reference = result.reference
    t0_ns = int(reference.stamps_ns[0]) if len(reference) else 0
    ref_model_m = site.apply_positions(reference.positions_xyz)
    base_m = np.round((ref_model_m.min(axis=0) + ref_model_m.max(axis=0)) / 2.0)
    scale = units.per_metre
    decimals = vertex_decimals(units)

    def local(positions_xyz: FloatArray) -> FloatArray:
        out: FloatArray = (site.apply_positions(positions_xyz) - base_m) * scale
        return out

    min_gap_ns = round(result.config.max_gap_s * _NS_PER_S)
    ref_losses = reference.tracking_losses(min_gap_ns)
    bins = error_bins(result)
    unit = error_unit(result)  # one unit for every error the viewer shows (and the CAD labels)
    paths: list[dict[str, object]] = []
    worst: list[dict[str, object]] = []
    beyond: list[dict[str, object]] = []
    verdicts: list[dict[str, object]] = []

    ref_breaks = path_breaks(reference.stamps_ns, min_gap_ns=min_gap_ns, losses=ref_losses)
    kept = display_indices(reference.positions_xyz, ref_breaks)
    paths.append(
        {
            "name": display_text(reference.name or "reference"),
            "kind": "reference",
            "source": display_text(reference.source or ""),
            "color": hex_colour(palette_color(0)),
            "poses": len(reference),
            "t": flat_rounded((reference.stamps_ns[kept] - t0_ns) / _NS_PER_S, _TIME_DECIMALS),
            "xyz": flat_rounded(local(reference.positions_xyz[kept]), decimals),
            "breaks": _display_breaks(ref_breaks, kept),
        }
    )
    for k, est in enumerate(result.estimates, start=1):
        name = display_text(est.name or f"estimate {k}")
        stamps = est.association.reference.stamps_ns
        errors = est.ate_translation.values
        breaks = path_breaks(stamps, min_gap_ns=min_gap_ns, losses=ref_losses)
        kept = display_indices(
            est.aligned.positions_xyz, breaks, errors_m=errors, must_keep=_must_keep(est)
        )
        stats = est.ate_translation.stats
        paths.append(
            {
                "name": name,
                "kind": "estimate",
                "source": display_text(est.estimate.source or ""),
                "color": hex_colour(palette_color(k)),
                "poses": len(stamps),
                "t": flat_rounded((stamps[kept] - t0_ns) / _NS_PER_S, _TIME_DECIMALS),
                "xyz": flat_rounded(local(est.aligned.positions_xyz[kept]), decimals),
                "ref": flat_rounded(local(est.association.reference.positions_xyz[kept]), decimals),
                "err": flat_rounded(errors[kept], ERROR_DECIMALS),
                "breaks": _display_breaks(breaks, kept),
                "ate": {"rmse": stats.rmse, "max": stats.max} if len(errors) else None,
                "uncertainty": _uncertainty(est.aligned, kept, site, scale),
            }
        )
        labels_name = name if len(result.estimates) > 1 else ""
        worst += _worst_labels(
            est.worst, kept, path=len(paths) - 1, name=labels_name, unit=unit, result=result
        )
        beyond += _beyond(est, kept, path=len(paths) - 1, name=name, unit=unit)
        verdicts.append(_verdict(est, name, unit))
    tolerance = result.config.tolerance
    return {
        "generator": f"loceval {__version__}",
        "title": options.title,
        "units": units.value,
        "per_metre": scale,
        "frame": reference.frame_id or "reference frame",
        "base": (base_m * scale).tolist(),
        "crs": options.crs,
        "t0_ns": str(t0_ns),
        "coordinate_decimals": coordinate_decimals(scale),
        "lengths": unit.to_dict(),
        "bins": bins_json(bins),
        "legend": scale_words(result),
        "tolerance": None
        if tolerance is None
        else {"distance_m": tolerance.distance_m, "share": tolerance.share},
        "verdicts": verdicts,
        "beyond": beyond,
        "beyond_total": sum(
            len(e.verdict.failing_spans) for e in result.estimates if e.verdict is not None
        ),
        "frame_building_up_to": FRAME_BUILDING_UP_TO,
        "building_warnings": [] if result.building is None else list(result.building.warnings),
        "excursion_color": hex_colour(EXCURSION_RGB),
        "paths": paths,
        "worst": worst,
        "anchors": _anchors(result, local, decimals),
        "excursions": [
            {
                "path": x.index + 1,  # the reference is path 0
                "label": display_text(x.label),
                "xyz": flat_rounded(local(x.positions_xyz), decimals),
                **x.figures,
            }
            for x in excursion_paths(result)
        ],
        "building": building_scene(options, base_m, scale, decimals),
        "spaces": _space_labels(result, local, decimals),
    }


def _worst_labels(
    ranked: tuple[WorstPose, ...],
    kept: IntArray,
    *,
    path: int,
    name: str,
    unit: LengthUnit,
    result: EvaluationResult,
) -> list[dict[str, object]]:
    """Every greatest error's label at its display vertex, numbered #1..#N by rank.

    The core lists distinct peaks (:func:`loceval.metrics.pose_errors.greatest_errors`),
    so the numbers have no gap and are the report's and the CAD files'. The viewer shows
    as many as fit without overlapping, the greatest first.
    """
    tolerance = result.config.tolerance
    out: list[dict[str, object]] = []
    for rank, worst in enumerate(ranked, start=1):  # a handful (--worst), not per pose
        index = int(np.searchsorted(kept, worst.index))
        within = tolerance is not None and worst.error <= tolerance.distance_m
        who = f"{name} " if name else ""
        out.append(
            {
                "path": path,
                "rank": rank,
                "index": min(index, len(kept) - 1),
                "label": f"{who}#{rank} {unit.text(worst.error)}",
                "title": f"{who}#{rank}: {unit.text(worst.error)} at t = {worst.t_s:.1f} s",
                "within": within,
            }
        )
    return out


def _must_keep(est: EstimateResult) -> IntArray:
    """Poses every display set keeps: the greatest errors and both edges of each stretch.

    A stretch beyond the tolerance starts and ends at drawn vertices, and so do its
    neighbours within it: its colour is drawn where it is and nowhere else.
    """
    keep = [w.index for w in est.worst]
    if est.verdict is not None:
        for s in est.verdict.failing_spans[:MAX_STRETCHES]:  # one per listed stretch
            keep += [s.first_index - 1, s.first_index, s.last_index, s.last_index + 1]
            keep.append(s.max_error_index)
    return np.array(keep, dtype=np.intp)


def _beyond(
    est: EstimateResult, kept: IntArray, *, path: int, name: str, unit: LengthUnit
) -> list[dict[str, object]]:
    """The stretches beyond the tolerance, worst first, with their display vertices."""
    verdict = est.verdict
    if verdict is None:
        return []
    tolerance_m = verdict.tolerance.distance_m
    out: list[dict[str, object]] = []
    for rank, s in enumerate(verdict.failing_spans[:MAX_STRETCHES], start=1):
        first, last, at = np.searchsorted(kept, [s.first_index, s.last_index, s.max_error_index])
        out.append(
            {
                "estimate": name,
                "path": path,
                "rank": rank,
                "t0_s": round(s.start_s, _TIME_DECIMALS),
                "t1_s": round(s.end_s, _TIME_DECIMALS),
                "duration_s": round(s.duration_s, _TIME_DECIMALS),
                "length_m": round(s.length_m, 3),
                "max_error_m": round(s.max_error_m, ERROR_DECIMALS),
                "max_error_s": round(s.max_error_s, _TIME_DECIMALS),
                "space": s.space,
                "i0": int(first),
                "i1": int(last),
                "at": int(min(at, len(kept) - 1)),
                "text": (
                    f"{s.words(tolerance_m)}: from t = {s.start_s:.1f} s, "
                    f"{s.length_m:.1f} m travelled, worst {unit.text(s.max_error_m)}"
                ),
            }
        )
    return out


def _verdict(est: EstimateResult, name: str, unit: LengthUnit) -> dict[str, object]:
    """An estimate's verdict as the viewer's header shows it."""
    verdict = est.verdict
    if verdict is None:
        rmse = est.ate_translation.stats.rmse if len(est.ate_translation) else math.nan
        return {
            "name": name,
            "status": "none",
            "text": f"no tolerance; typical error (RMSE) {unit.text(rmse)}",
        }
    interval = ""
    if verdict.share_ci95 is not None:
        lo, hi = verdict.share_ci95
        interval = f", interval {lo * 100:.1f}-{hi * 100:.1f} %"
    tol = verdict.tolerance
    return {
        "name": name,
        "status": verdict.result,
        "share_within": verdict.share_within,
        "ci95": None if verdict.share_ci95 is None else list(verdict.share_ci95),
        "text": (
            f"{verdict.share_within * 100:.1f} % within {tol.distance_m:g} m "
            f"({tol.share * 100:g} % required{interval})"
        ),
    }


def _uncertainty(
    aligned: Trajectory, kept: IntArray, site: SimilarityTransform, scale: float
) -> dict[str, list[float] | list[int]] | None:
    """2-sigma horizontal ellipses of the reported position covariance at some display vertices.

    The covariance follows the alignment and the site transform (``J Σ Jᵀ``,
    :meth:`Trajectory.transformed`); each ellipse is the eigen-decomposition of its x-y block
    (vectorised over the vertices): semi-axes ``2 sqrt(λ)`` in output units and the major
    axis's angle from x, radians. At most :data:`_MAX_ELLIPSES` vertices, evenly spread.

    Returns:
        ``{"index": display indices, "ellipse": [a, b, angle, ...]}``, or None without
        covariances.
    """
    if aligned.cov6 is None or not len(kept):
        return None
    pick = np.unique(np.linspace(0, len(kept) - 1, min(len(kept), _MAX_ELLIPSES)).round())
    pick = pick.astype(np.intp)
    cov = aligned.select(kept[pick]).transformed(site).cov6
    if cov is None:
        return None
    values, vectors = np.linalg.eigh(cov[:, :2, :2])  # ascending: the major axis is last
    major = _SIGMAS * np.sqrt(np.clip(values[:, 1], 0.0, None)) * scale
    minor = _SIGMAS * np.sqrt(np.clip(values[:, 0], 0.0, None)) * scale
    angle = np.arctan2(vectors[:, 1, 1], vectors[:, 0, 1])
    ellipse = np.column_stack([major, minor, angle])
    return {"index": pick.tolist(), "ellipse": flat_rounded(ellipse, 6)}


def _space_labels(
    result: EvaluationResult, local: Callable[[FloatArray], FloatArray], decimals: int
) -> list[dict[str, object]]:
    """The building's named spaces: a label at each footprint's centre, at its floor."""
    if result.building is None or not result.building.spaces:
        return []
    out: list[dict[str, object]] = []
    for space in result.building.spaces:  # tens to hundreds
        x, y = space.outline_xy.mean(axis=0)
        z = (
            space.floor_m
            if math.isfinite(space.floor_m)
            else float(result.reference.positions_xyz[:, 2].min())
        )
        out.append(
            {"name": space.name, "xyz": flat_rounded(local(np.array([[x, y, z]]))[0], decimals)}
        )
    return out


def _anchors(
    result: EvaluationResult, local: Callable[[FloatArray], FloatArray], decimals: int
) -> list[dict[str, object]]:
    """The radio anchors of a ranging evaluation, placed like the paths."""
    if result.ranging is None or not result.ranging.anchors:
        return []
    xyz = np.array([a.position_xyz for a in result.ranging.anchors], dtype=np.float64)
    placed = local(xyz)
    return [
        {"id": display_text(a.id), "xyz": flat_rounded(placed[i], decimals)}
        for i, a in enumerate(result.ranging.anchors)
    ]


def building_scene(
    options: ExportOptions, base_m: FloatArray, scale: float, decimals: int
) -> dict[str, object] | None:
    """The building model as a mesh, or a DXF floor plan as lines, in local model units."""
    if options.building is None:
        return None
    underlay = read_underlay(options.building, units=options.units, up=options.building_up)
    source = Path(options.building).name
    if not isinstance(underlay, BuildingModel):  # a DXF floor plan
        ends = underlay.segments_m.reshape(-1, 2)
        z = np.zeros((len(ends), 1))
        xyz = (np.hstack([ends, z]) - base_m) * scale
        xyz[:, 2] = 0.0
        return {"kind": "plan", "source": source, "segments": flat_rounded(xyz, decimals)}
    faces = underlay.faces[:_MAX_BUILDING_FACES]
    return {
        "kind": "mesh",
        "source": source,
        "faces_dropped": int(len(underlay.faces) - len(faces)),
        "positions": flat_rounded((underlay.vertices_m - base_m) * scale, decimals),
        "index": faces.ravel().tolist(),
    }
