"""Options shared by the exporters: model placement for CAD files, report settings.

The user-facing ones (units, site, simplification, building) are declared with the other
options in :data:`loceval.options.OPTIONS`; :class:`Units` is re-exported from there.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from loceval.geometry import SimilarityTransform
from loceval.options import Units, choice_default, number_default

__all__ = ["ExportOptions", "Units"]

_DEFAULT_UNITS = Units(choice_default("units"))


@dataclass(frozen=True, slots=True)
class ExportOptions:
    """How an evaluation becomes files.

    Attributes:
        units: output length units of CAD files.
        site: maps the evaluation frame (the reference's frame, REP 103 Z-up metres) onto
            the building model's coordinates (metres); identity by default.
        simplify_m: largest deviation, in metres, that polyline simplification may
            introduce (0 keeps every vertex).
        building: a building mesh (OBJ/PLY/STL/GLB) to put in the glTF scene, if any.
        evaluation_id: the id named in every file's metadata.
        title: a human title for reports and file metadata.
        templates_dir: where the report templates live (``templates/`` by default).
    """

    units: Units = _DEFAULT_UNITS
    site: SimilarityTransform = field(default_factory=SimilarityTransform.identity)
    simplify_m: float = number_default("simplify_m")
    building: Path | None = None
    evaluation_id: str = "local"
    title: str = "loceval evaluation"
    templates_dir: Path | None = None
