"""Control points, measured positions and error lines in model coordinates, for CAD files.

What ``paths.dxf`` (:mod:`exporters.cad.dxf_points`), ``paths.3dm``, ``paths.3dm.json``
(:mod:`exporters.cad.rhino_points`) and ``paths.glb`` (:mod:`exporters.cad.gltf_points`) of an
evaluation against control points show, computed once: the same site transform
(``options.site``), units, layer names, colours and labels in every format.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from exporters.colours import RGB, estimate_colour, layer_name, unique_layer_names
from exporters.options import ExportOptions, Units
from loceval._version import __version__
from loceval.checkpoint_evaluation import CheckpointEvaluation
from loceval.core.arrays import BoolArray, FloatArray

__all__ = [
    "ALIGNMENT_RGB",
    "POINTS_LAYER",
    "POINTS_RGB",
    "PlacedControlPoints",
    "PlacedVisits",
    "error_label",
    "place_control_points",
]

POINTS_LAYER: Final = "control points"
"""The layer of the surveyed points and their ids."""
POINTS_RGB: Final[RGB] = (255, 255, 255)
ALIGNMENT_RGB: Final[RGB] = (128, 128, 128)
"""Visits that fixed the alignment (not scored) are grey, as in the DXF (ACI 8)."""


def error_label(point_id: str, error_m: float, *, used_for_alignment: bool) -> str:
    """Return an error line's label, ``P01 12.3 mm`` (``(alignment)`` appended if so)."""
    text = f"{point_id} {error_m * 1000:.1f} mm"
    return f"{text} (alignment)" if used_for_alignment else text


def _rgb(hex_colour: str) -> RGB:
    text = hex_colour.lstrip("#")
    return int(text[0:2], 16), int(text[2:4], 16), int(text[4:6], 16)


@dataclass(frozen=True, slots=True, eq=False)
class PlacedVisits:
    """One estimate's visits in model coordinates (output units).

    Attributes:
        name: the estimate's name (``estimate <k>`` when it has none).
        measured_layer: ``<name> measured``.
        errors_layer: ``<name> errors``.
        color_rgb: the estimate's colour (the report's and the DXF's).
        point_ids: (N,) the visited points.
        surveyed: (N, 3) the surveyed points.
        measured: (N, 3) the measured (aligned median) positions.
        labels: (N,) the error labels (:func:`error_label`).
        alignment: (N,) the visit fixed the alignment (drawn grey).
    """

    name: str
    measured_layer: str
    errors_layer: str
    color_rgb: RGB
    point_ids: tuple[str, ...]
    surveyed: FloatArray
    measured: FloatArray
    labels: tuple[str, ...]
    alignment: BoolArray

    def colours(self) -> list[RGB]:
        """Return each visit's colour: grey for alignment visits, else the estimate's."""
        return [ALIGNMENT_RGB if a else self.color_rgb for a in self.alignment.tolist()]


@dataclass(frozen=True, slots=True, eq=False)
class PlacedControlPoints:
    """An evaluation against control points in model coordinates (what every CAD file shows).

    Attributes:
        units: output length units.
        base_point_m: (3,) model metres the local coordinates are relative to (the surveyed
            points' bounding-box centre, rounded to whole metres).
        evaluation_id: the evaluation's id.
        title: a human title.
        source: the survey file.
        ids: (M,) the control point ids.
        points: (M, 3) the surveyed points, model coordinates, output units.
        estimates: one entry per estimate, in evaluation order.
        metadata: the file-level metadata every format stores (JSON-ready).
    """

    units: Units
    base_point_m: FloatArray
    evaluation_id: str
    title: str
    source: str
    ids: tuple[str, ...]
    points: FloatArray
    estimates: tuple[PlacedVisits, ...]
    metadata: dict[str, object]

    @property
    def base_point(self) -> FloatArray:
        """Return the base point in model coordinates, output units, (3,)."""
        out: FloatArray = self.base_point_m * self.units.per_metre
        return out


def place_control_points(
    evaluation: CheckpointEvaluation, options: ExportOptions
) -> PlacedControlPoints:
    """Map the points, the measured positions and the error lines to model coordinates.

    Args:
        evaluation: the evaluation.
        options: units, site transform, title, id.

    Returns:
        The placement.
    """
    units = Units(options.units)
    site = options.site

    def model(xyz: FloatArray) -> FloatArray:
        out: FloatArray = site.apply_positions(np.atleast_2d(xyz)) * units.per_metre
        return out

    points = evaluation.points
    points_m = site.apply_positions(points.positions_xyz)
    base_m = np.round((points_m.min(axis=0) + points_m.max(axis=0)) / 2.0)
    names = [e.name or f"estimate {k}" for k, e in enumerate(evaluation.estimates, start=1)]
    layers = unique_layer_names([POINTS_LAYER, *(layer_name(n) for n in names)])[1:]
    estimates = []
    for k, (entry, layer) in enumerate(zip(evaluation.estimates, layers, strict=True)):
        visits = entry.result.visits
        surveyed = np.array([v.surveyed_xyz for v in visits], dtype=np.float64).reshape(-1, 3)
        measured = np.array([v.measured_xyz for v in visits], dtype=np.float64).reshape(-1, 3)
        estimates.append(
            PlacedVisits(
                name=layer,
                measured_layer=f"{layer} measured",
                errors_layer=f"{layer} errors",
                color_rgb=_rgb(estimate_colour(k)),
                point_ids=tuple(v.point_id for v in visits),
                surveyed=model(surveyed) if visits else surveyed,
                measured=model(measured) if visits else measured,
                labels=tuple(
                    error_label(v.point_id, v.error_m, used_for_alignment=v.used_for_alignment)
                    for v in visits
                ),
                alignment=np.array([v.used_for_alignment for v in visits], dtype=bool),
            )
        )
    metadata: dict[str, object] = {
        "generator": f"loceval {__version__}",
        "evaluation_id": options.evaluation_id,
        "title": options.title,
        "created_at": evaluation.created_at,
        "units": units.value,
        "kind": "control points",
        "frame": {
            "evaluation_frame": "building frame of the control points",
            "convention": "REP 103: x forward, y left, z up, metres",
            "model": "building model coordinates, z up",
            "site_matrix_m": site.as_matrix().tolist(),
        },
        "base_point": (base_m * units.per_metre).tolist(),
        "simplify_tolerance_m": 0.0,
        "max_deviation_m": 0.0,
        "source": points.source,
        "estimates": [e.name for e in estimates],
    }
    return PlacedControlPoints(
        units=units,
        base_point_m=base_m,
        evaluation_id=options.evaluation_id,
        title=options.title,
        source=points.source,
        ids=points.ids,
        points=model(points.positions_xyz),
        estimates=tuple(estimates),
        metadata=metadata,
    )
