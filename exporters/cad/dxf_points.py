"""DXF (R2013) of an evaluation against control points (written as ``paths.dxf``).

Layers, in model coordinates (the site transform applied, in the export units):

- ``control points``: a ``POINT`` and the id at each surveyed point;
- ``<estimate> measured``: a ``POINT`` at each visit's measured (aligned median) position;
- ``<estimate> errors``: a ``LINE`` from the surveyed point to the measured position of each
  visit, labelled with its 3D error in millimetres; visits that fixed the alignment are
  grey, scored visits are in the estimate's colour.

Lines are drawn at true scale (a CAD user zooms); the labels say the size. The metadata
(evaluation id, units, site) are ``$CUSTOMPROPERTY`` header entries, as in ``paths.dxf``.
"""

from __future__ import annotations

import io
import json
from collections.abc import Callable, Sequence
from typing import Final

import numpy as np
from ezdxf import colors
from ezdxf import units as dxf_units
from ezdxf.document import Drawing
from ezdxf.filemanagement import new as new_drawing
from ezdxf.lldxf.const import DXFError

from exporters.cad.points_placement import POINTS_LAYER, error_label
from exporters.colours import estimate_colour
from exporters.errors import ExportError
from exporters.options import ExportOptions, Units
from loceval._version import __version__
from loceval.checkpoint_evaluation import CheckpointEvaluation
from loceval.checkpoints.fit import VisitResult
from loceval.core.arrays import FloatArray

__all__ = ["POINTS_LAYER", "export_points_dxf"]

_INSUNITS: Final = {Units.MM: dxf_units.MM, Units.CM: dxf_units.CM, Units.M: dxf_units.M}
_PDMODE_CIRCLE_CROSS: Final = 35
_ALIGNMENT_ACI: Final = 8  # grey

ToModel = Callable[[FloatArray], list[tuple[float, float, float]]]
"""Evaluation-frame metres (N, 3) -> model coordinates in the export units."""


def export_points_dxf(evaluation: CheckpointEvaluation, options: ExportOptions) -> bytes:
    """Write the control points, the measured positions and the error lines as DXF.

    Raises:
        ExportError: ezdxf refused the drawing.
    """
    try:
        doc = _drawing(evaluation, options)
        stream = io.StringIO()
        doc.write(stream)
    except DXFError as err:
        msg = f"ezdxf could not write the DXF drawing ({err}); please report this."
        raise ExportError(msg) from err
    return stream.getvalue().encode("utf-8")


def _rgb(hex_colour: str) -> tuple[int, int, int]:
    text = hex_colour.lstrip("#")
    return int(text[0:2], 16), int(text[2:4], 16), int(text[4:6], 16)


def _drawing(evaluation: CheckpointEvaluation, options: ExportOptions) -> Drawing:
    per_metre = options.units.per_metre

    def model(xyz: FloatArray) -> list[tuple[float, float, float]]:
        placed = options.site.apply_positions(np.atleast_2d(xyz)) * per_metre
        return [(float(x), float(y), float(z)) for x, y, z in placed]

    doc = new_drawing("R2013", setup=False, units=_INSUNITS[options.units])
    doc.header["$MEASUREMENT"] = 1
    doc.header["$LUNITS"] = 2
    doc.header["$PDMODE"] = _PDMODE_CIRCLE_CROSS
    doc.header["$PROJECTNAME"] = options.title
    for key, value in {
        "generator": f"loceval {__version__}",
        "evaluation_id": options.evaluation_id,
        "units": options.units.value,
        "site": options.site.to_dict(),
    }.items():
        doc.header.custom_vars.append(f"loceval.{key}", json.dumps(value))
    msp = doc.modelspace()
    points = evaluation.points
    surveyed = model(points.positions_xyz)
    spacing = points.min_spacing_m() if len(points) > 1 else 1.0
    text_h = float(np.clip(spacing / 10.0, 0.005, 1.0)) * per_metre
    doc.header["$PDSIZE"] = 0.6 * text_h
    layer = doc.layers.add(POINTS_LAYER, color=colors.WHITE)
    layer.description = f"loceval: surveyed control points ({points.source})"
    for pid, xyz in zip(points.ids, surveyed, strict=True):  # one entity pair per point
        msp.add_point(xyz, dxfattribs={"layer": POINTS_LAYER})
        msp.add_text(pid, height=text_h, dxfattribs={
            "layer": POINTS_LAYER, "insert": (xyz[0] + 0.4 * text_h, xyz[1] + 0.4 * text_h, xyz[2])
        })  # fmt: skip
    for k, entry in enumerate(evaluation.estimates):
        _add_estimate(doc, entry.name, k, entry.result.visits, to_model=model, text_h=text_h)
    return doc


def _add_estimate(
    doc: Drawing,
    name: str,
    index: int,
    visits: Sequence[VisitResult],
    *,
    to_model: ToModel,
    text_h: float,
) -> None:
    """Add the ``<name> measured`` and ``<name> errors`` layers of one estimate."""
    msp = doc.modelspace()
    rgb = _rgb(estimate_colour(index))
    label = name or f"estimate {index + 1}"
    measured_layer, errors_layer = f"{label} measured", f"{label} errors"
    layers = (
        (measured_layer, "measured positions (aligned medians)"),
        (errors_layer, "error lines, surveyed -> measured, labelled"),
    )
    for layer_name, what in layers:
        layer = doc.layers.add(layer_name)
        layer.rgb = rgb
        layer.description = f"loceval: {label}: {what}"
    for visit in visits:  # one entity group per visit
        start, end = to_model(np.array([visit.surveyed_xyz, visit.measured_xyz]))
        grey = {"color": _ALIGNMENT_ACI} if visit.used_for_alignment else {}
        msp.add_point(end, dxfattribs={"layer": measured_layer, **grey})
        msp.add_line(start, end, dxfattribs={"layer": errors_layer, **grey})
        text = error_label(
            visit.point_id, visit.error_m, used_for_alignment=visit.used_for_alignment
        )
        msp.add_text(text, height=0.5 * text_h, dxfattribs={
            "layer": errors_layer, "insert": (end[0], end[1] - 0.8 * text_h, end[2]), **grey
        })  # fmt: skip
