"""The viewer of an evaluation against control points: points, visits, error vectors, tracks.

The same page as a trajectory evaluation's (``templates/viewer/viewer.js``) with a scene of
another kind (``"mode": "checkpoints"``): each estimate's track, aligned onto the building
by its control-point alignment, in its palette colour (there is no reference path); the
surveyed control points with their ids; and every visit's error vector, from the surveyed
point to the measured (aligned median) position, coloured by the error on the report's
scale (visits that fixed the alignment grey, as in the CAD files). The timeline moves along
the tracks; ``data-errors`` holds, for each estimate, the error of the visit in progress.
Everything is placed as :func:`exporters.cad.points_placement.place_control_points` places it:
the site transform, the output units, the survey's bounding-box centre as base point.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from exporters.cad.site import check_options
from exporters.colours import ate_bins, hex_colour, palette_color
from exporters.options import ExportOptions, Units
from exporters.viewer.page import DEFAULT_TEMPLATES_DIR, scene_fragment, viewer_page
from exporters.viewer.reduce import display_indices
from exporters.viewer.scene import (
    bins_json,
    building_scene,
    flat_rounded,
    vertex_decimals,
)
from loceval import __version__
from loceval.checkpoint_evaluation import CheckpointEvaluation
from loceval.core.arrays import FloatArray
from loceval.core.display import display_text
from loceval.core.gaps import path_breaks
from loceval.core.lengths import coordinate_decimals, length_unit

__all__ = ["checkpoint_scene", "export_checkpoint_viewer_html"]

_NS_PER_S: Final = 1_000_000_000
_GREY: Final = "#808080"


def checkpoint_scene(evaluation: CheckpointEvaluation, options: ExportOptions) -> dict[str, object]:
    """Return the viewer's document of an evaluation against control points (JSON-ready).

    Raises:
        ExportOptionsError: bad units or site, or an unreadable building file.
    """
    check_options(options)
    units = Units(options.units)
    site = options.site
    scale = units.per_metre
    decimals = vertex_decimals(units)
    points = evaluation.points
    points_m = site.apply_positions(points.positions_xyz)
    base_m = np.round((points_m.min(axis=0) + points_m.max(axis=0)) / 2.0)

    def local(xyz: FloatArray) -> FloatArray:
        out: FloatArray = (site.apply_positions(np.atleast_2d(xyz)) - base_m) * scale
        return out

    firsts = [int(e.estimate.stamps_ns[0]) for e in evaluation.estimates if len(e.estimate)]
    t0_ns = min(firsts, default=0)
    min_gap_ns = round(evaluation.config.max_gap_s * _NS_PER_S)
    bins = ate_bins(evaluation.config.thresholds_m)
    edges = np.array([b.high_m for b in bins[:-1]])
    paths: list[dict[str, object]] = []
    visits: list[dict[str, object]] = []
    for k, entry in enumerate(evaluation.estimates):
        track = entry.estimate.transformed(entry.result.transform)
        breaks = path_breaks(track.stamps_ns, min_gap_ns=min_gap_ns)
        kept = display_indices(track.positions_xyz, breaks)
        crossed = np.concatenate(([0], np.cumsum(breaks, dtype=np.int64)))
        name = display_text(entry.name or f"estimate {k + 1}")
        paths.append(
            {
                "name": name,
                "kind": "track",
                "source": display_text(entry.estimate.source or ""),
                "color": hex_colour(palette_color(k + 1)),
                "poses": len(track),
                "t": flat_rounded((track.stamps_ns[kept] - t0_ns) / _NS_PER_S, 6),
                "xyz": flat_rounded(local(track.positions_xyz[kept]), decimals),
                "breaks": np.flatnonzero(crossed[kept[1:]] > crossed[kept[:-1]]).tolist(),
            }
        )
        for visit in entry.result.visits:  # one per visit (tens to hundreds), not per pose
            error = float(visit.error_m)
            colour = bins[int(np.searchsorted(edges, error, side="left"))].color_rgb
            visits.append(
                {
                    "path": k,
                    "id": display_text(visit.point_id),
                    "t0": round((visit.start_ns - t0_ns) / _NS_PER_S, 6),
                    "t1": round((visit.end_ns - t0_ns) / _NS_PER_S, 6),
                    "surveyed": flat_rounded(local(np.array(visit.surveyed_xyz)), decimals),
                    "measured": flat_rounded(local(np.array(visit.measured_xyz)), decimals),
                    "error": error,
                    "alignment": bool(visit.used_for_alignment),
                    "color": _GREY if visit.used_for_alignment else hex_colour(colour),
                }
            )
    placed = local(points.positions_xyz)
    return {
        "generator": f"loceval {__version__}",
        "mode": "checkpoints",
        "title": options.title,
        "units": units.value,
        "per_metre": scale,
        "frame": "building frame of the control points",
        "base": (base_m * scale).tolist(),
        "crs": options.crs,
        "t0_ns": str(t0_ns),
        "coordinate_decimals": coordinate_decimals(scale),
        "lengths": length_unit(
            float(v.error_m) for e in evaluation.estimates for v in e.result.visits
        ).to_dict(),
        "bins": bins_json(bins),
        "paths": paths,
        "worst": [],
        "anchors": [],
        "controls": {
            "points": [
                {"id": display_text(pid), "xyz": flat_rounded(placed[i], decimals)}
                for i, pid in enumerate(points.ids)
            ],
            "visits": visits,
        },
        "building": building_scene(options, base_m, scale, decimals),
    }


def export_checkpoint_viewer_html(
    evaluation: CheckpointEvaluation, options: ExportOptions
) -> bytes:
    """Return ``viewer.html`` of an evaluation against control points (one closed file).

    Raises:
        ExportError: the viewer's scripts or the vendored three.js are missing or damaged.
        ExportOptionsError: bad units or site, or an unreadable building file.
    """
    folder = options.templates_dir or DEFAULT_TEMPLATES_DIR
    fragment = scene_fragment(checkpoint_scene(evaluation, options), folder)
    visits = sum(len(e.result.visits) for e in evaluation.estimates)
    subtitle = (
        f"{len(evaluation.estimates)} estimate(s), {visits} visits of "
        f"{len(evaluation.points.ids)} control points · units {options.units} · "
        "drag to pan or turn, wheel to zoom, click a point for its figures"
    )
    return viewer_page(fragment, title=options.title, subtitle=subtitle)
